"""Photos exposed apart, brought to one exposure (exposure_match.py): the gains from EXIF, the
matching through the camera curve, and a capture's crops made at one exposure."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.crop import CropConfig, prepare_view
from lirm.engine.capture.exposure_match import exposure_gains, match_exposure
from lirm.engine.cli import main
from lirm.engine.lighting.camera_response import display_to_radiance, radiance_to_display_torch

from .test_exif_exposure import EXPOSURE_TIME, F_NUMBER, ISO, _exif


def test_gains_bring_every_photo_to_the_most_exposed_one():
    gains = exposure_gains({"a": -8.0, "b": -9.0, "c": -7.5})
    assert gains == pytest.approx({"a": 2 ** 0.5, "b": 2 ** 1.5, "c": 1.0})
    assert exposure_gains({"a": -8.0, "b": -8.05}) is None  # EXIF's rounding of one exposure
    assert exposure_gains({"a": -8.0, "b": None, "c": -9.0}) is None  # one photo's exposure unknown: no common place
    assert exposure_gains({"a": -8.0}) is None


@pytest.mark.parametrize("response", ["aces", "srgb"])
def test_matching_scales_the_linear_light_keeps_clipped_pixels_and_alpha(response):
    g = np.random.default_rng(0)
    image = np.concatenate([g.integers(20, 200, (8, 8, 3)), np.full((8, 8, 1), 77)], -1).astype(np.uint8)
    image[0, 0, :3] = 255
    matched = match_exposure(image, 2.0, response)
    assert matched.dtype == np.uint8 and (matched[..., 3] == 77).all() and (matched[0, 0, :3] == 255).all()
    before, after = display_to_radiance(image[..., :3] / 255.0, response), display_to_radiance(matched[..., :3] / 255.0, response)
    unclipped = (matched[..., :3] < 250) & (before > 1e-3)  # (ACES's toe maps the darkest values to 0)
    ratio = after[unclipped] / before[unclipped]
    assert np.median(ratio) == pytest.approx(2.0, rel=0.02) and np.abs(ratio - 2.0).max() < 0.25  # 8-bit steps
    assert match_exposure(image, 1.0, response) is image
    floats = match_exposure(image[..., :3] / 255.0, 2.0, response)
    assert np.abs(floats * 255 - matched[..., :3]).max() <= 0.5 + 1e-6
    with pytest.raises(ValueError, match="positive"):
        match_exposure(image, 0.0, response)
    # One gain a channel (a white balance): a darkened channel keeps its clipped pixels clipped.
    balanced = match_exposure(image, [0.8, 1.0, 1.25], response)
    assert (balanced[0, 0, :3] == 255).all() and np.abs(balanced[..., 1].astype(int) - image[..., 1]).max() <= 2  # (the curve and back)
    inside = (image[..., :3] > 40) & (image[..., :3] < 200)
    assert (balanced[..., 0][inside[..., 0]] <= image[..., 0][inside[..., 0]]).all()
    assert (balanced[..., 2][inside[..., 2]] >= image[..., 2][inside[..., 2]]).all()


def test_a_capture_exposed_apart_is_cropped_at_one_exposure(shared_data, tmp_path, capsys):
    """Lego renders as a phone with automatic exposure would have taken them: each darkened in linear
    light by its EXIF exposure below the most exposed one. The crops come back as the renders."""
    lego = shared_data / "synth_nerf_lego_train"
    photos = tmp_path / "photos"
    photos.mkdir()
    times = [1 / 100, 1 / 200, 1 / 141, 1 / 100]
    originals = {}
    for k, seconds in enumerate(times):
        source = lego / "train" / f"r_{5 * k}.png"
        rgba = np.asarray(Image.open(source).convert("RGBA"))
        originals[f"r_{5 * k}"] = rgba
        radiance = display_to_radiance(rgba[..., :3] / 255.0) * (seconds / max(times))  # the product's curve (ACES)
        darker = radiance_to_display_torch(torch.from_numpy(radiance)).numpy()
        shot = np.concatenate([np.round(darker * 255).astype(np.uint8), rgba[..., 3:]], -1)
        tags = {EXPOSURE_TIME: Fraction(seconds).limit_denominator(100000), F_NUMBER: 2.0, ISO: 100}
        Image.fromarray(shot).save(photos / source.name, exif=_exif(tags).tobytes())
    out = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(out), "--masks", "alpha", "--size", "64",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    report = capsys.readouterr().out
    assert "matched to the most exposed photo" in report and "lock the exposure" in report, report
    capture = Capture.open(out)
    crops = [e for e in capture.history if e.get("action") == "crops"][-1]
    assert crops["exposure_matched"] and crops["brightened_up_to_stops"] == pytest.approx(1.0, abs=0.01)
    for frame_id in sorted(capture.frames):
        view = capture.read_prepared(frame_id)
        stem = Path(capture.frames[frame_id].record.original).stem
        truth = prepare_view(frame_id, originals[stem][..., :3], capture.read_mask(frame_id), capture.cameras[frame_id],
                             CropConfig(size=64))
        inside = view.mask > 0.99
        error = np.abs(view.image_masked - truth.image_masked)[inside].mean()
        assert error < 1.5 / 255, (frame_id, error * 255)


def test_the_report_says_whether_the_photos_were_matched():
    from lirm.engine.capture.exif_exposure import exposure_note

    matched, warned = exposure_note([-8.0, -9.0, -8.5])
    assert warned and "matched to the most exposed photo" in matched and "lock the exposure" in matched
    unmatched, _ = exposure_note([-8.0, None, -9.0])
    assert "not matched by EXIF: 1 photo says nothing of its exposure" in unmatched and "backgrounds they share" in unmatched
    small, warned = exposure_note([-8.0, -8.3])
    assert not warned and "matched" in small and "lock" not in small
    same, _ = exposure_note([-8.0, -8.05])
    assert "matched" not in same
