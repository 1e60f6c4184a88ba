"""Each photo's exposure read from the surroundings the photos share (exposure_estimate.py): photos of
a real HDRI's surroundings, each exposed by its own stops, through the product's camera curve."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.assets.environment_files import load_environment_file
from lirm.engine.cameras import orbit_cameras
from lirm.engine.capture.exposure_estimate import COLOUR_NOISE_STOPS, ESTIMATE_NOISE_STOPS, estimate_exposure_stops
from lirm.engine.lighting.camera_response import radiance_to_display
from lirm.engine.lighting.capture_lighting import CaptureLightingConfig


def _photos(environment, cameras, stops, config, balance=None):
    """What each camera saw of the surroundings (placed on the proxy sphere, as the estimate places
    them), its linear light times 2^stops (and its red, green, blue times 2^balance), through the
    camera curve into 8 bits; a disc in the middle is the object (masked)."""
    radius = config.proxy_radius * float(np.median([np.linalg.norm(c.center) for c in cameras]))
    scale = 0.18 / float(np.median(environment.radiance.mean(-1)))  # metered on the surroundings
    images, masks = {}, {}
    for k, (camera, s) in enumerate(zip(cameras, stops)):
        ys, xs = np.mgrid[0:camera.height, 0:camera.width]
        origins, directions = camera.rays_at(np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], -1))
        b = np.sum(origins * directions, 1)
        t = -b + np.sqrt(b * b - (np.sum(origins * origins, 1) - radius * radius))
        radiance = environment.lookup(origins + directions * t[:, None]) * scale * 2.0 ** s
        if balance is not None:
            radiance = radiance * 2.0 ** np.asarray(balance[k])
        display = radiance_to_display(radiance, config.response).reshape(camera.height, camera.width, 3)
        images[f"p{k}"] = np.clip(np.round(display * 255.0), 0, 255).astype(np.uint8)
        mask = np.zeros((camera.height, camera.width), np.uint8)
        mask[(ys - camera.height / 2) ** 2 + (xs - camera.width / 2) ** 2 < (camera.height / 4) ** 2] = 255
        masks[f"p{k}"] = mask
    return images, masks, {f"p{k}": c for k, c in enumerate(cameras)}


@pytest.fixture(scope="module")
def forest(shared_data):
    return load_environment_file(shared_data / "envmaps" / "forest_slope_1k.hdr")


@pytest.mark.parametrize("surroundings", ["forest_slope_1k", "studio_small_03_1k", "st_fagans_interior_1k"])
def test_exposures_apart_come_back_from_the_backgrounds(shared_data, surroundings):
    config = CaptureLightingConfig()
    cameras = orbit_cameras(12, 15.0, 3.0, 128, 96, 70.0)
    truth = np.random.default_rng(3).uniform(-1.0, 1.0, len(cameras))
    environment = load_environment_file(shared_data / "envmaps" / f"{surroundings}.hdr")
    # Each photo balanced on its own too: red and blue up to 15% off, in opposite directions.
    tint = np.random.default_rng(4).uniform(-0.2, 0.2, len(cameras))
    balance = np.stack([tint, np.zeros_like(tint), -tint], 1)
    estimate = estimate_exposure_stops(*_photos(environment, cameras, truth, config, balance), config)
    assert estimate is not None and estimate.pairs >= len(cameras)
    found = np.array([estimate.stops[f"p{k}"] for k in range(len(cameras))])
    assert abs(found.mean()) < 1e-6  # only differences are seen: the mean is fixed
    # (the tint moves the luminance too, by 0.14 x its stops: 0.03 EV at most here)
    assert np.abs(found - (truth - truth.mean())).max() < 0.1, (found, truth - truth.mean())
    assert estimate.spread == pytest.approx(truth.max() - truth.min(), abs=0.12)
    # The balance: each photo's channels against its own mean, against the shoot's average.
    expected = balance - balance.mean(1, keepdims=True)
    expected -= expected.mean(0)
    colour = np.array([estimate.colour_stops[f"p{k}"] for k in range(len(cameras))])
    assert np.abs(colour - expected).max() < 0.02, np.abs(colour - expected).max()
    assert estimate.colour_worth_matching


def test_photos_at_one_exposure_are_found_at_one_exposure(forest):
    config = CaptureLightingConfig()
    cameras = orbit_cameras(8, 25.0, 3.0, 128, 96, 70.0)
    estimate = estimate_exposure_stops(*_photos(forest, cameras, np.zeros(len(cameras)), config), config)
    assert estimate is not None and estimate.spread < ESTIMATE_NOISE_STOPS / 2, estimate.stops
    assert estimate.colour_spread < COLOUR_NOISE_STOPS / 2 and not estimate.colour_worth_matching, estimate.colour_stops


def test_photos_that_share_no_surroundings_have_no_estimate(forest):
    """Two narrow views back to back see nothing in common: neither exposure has a place."""
    config = CaptureLightingConfig()
    cameras = orbit_cameras(2, 0.0, 3.0, 64, 48, 20.0)
    images, masks, by_frame = _photos(forest, cameras, [0.0, 1.0], config)
    assert estimate_exposure_stops(images, masks, by_frame, config) is None
    assert estimate_exposure_stops({"p0": images["p0"]}, masks, by_frame, config) is None


@pytest.mark.slow
def test_a_shoot_exposed_apart_without_exif_is_cropped_at_one_exposure(tmp_path, shared_data, gl_context, capsys):
    """The demo's mug on its gravel floor under a real sky, every other photo 1 EV darker (the
    product's camera curve), some balanced warmer or cooler (red and blue 11% apart), saved without
    EXIF: the capture reads the exposures and balances from the floor and sky the photos share, and its
    crops come back as the photos taken at one exposure and balance."""
    import json

    import cv2

    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.capture.crop import CropConfig, prepare_view
    from lirm.engine.capture.exposure_match import ESTIMATED_EXPOSURE_KEY
    from lirm.engine.cli import main
    from lirm.engine.lighting.camera_response import display_to_radiance
    from lirm.engine.synth.capture_scene import SyntheticCaptureConfig, render_synthetic_capture
    from lirm.renderer.pbr_renderer import PBRRenderer

    renderer = PBRRenderer(gl_context)
    try:
        sky = load_environment_file(shared_data / "envmaps" / "kiara_1_dawn_1k.hdr")
        shoot = render_synthetic_capture(renderer, sky, SyntheticCaptureConfig(views=10, width=320, height=240))
    finally:
        renderer.release()
    photos, masks = tmp_path / "photos", tmp_path / "masks"
    photos.mkdir()
    masks.mkdir()
    darker = {k: i % 2 == 1 for i, k in enumerate(sorted(shoot.images))}
    tints = dict(zip(sorted(shoot.images), 0.15 * np.array([1, -1, 0, 0, 1, -1, 0, -1, 1, 0])))  # (their mean: 0)
    frames = []
    for k, image in shoot.images.items():
        gain = np.array([2.0 ** tints[k], 1.0, 2.0 ** -tints[k]]) * (0.5 if darker[k] else 1.0)
        shot = np.clip(np.round(radiance_to_display(display_to_radiance(image / 255.0) * gain) * 255), 0, 255).astype(np.uint8)
        cv2.imwrite(str(photos / f"shot_{k}.png"), cv2.cvtColor(shot, cv2.COLOR_RGB2BGR))
        cv2.imwrite(str(masks / f"shot_{k}.png"), shoot.masks[k])
        frames.append({"file_path": f"shot_{k}.png", **shoot.cameras[k].to_dict()})
    (tmp_path / "transforms.json").write_text(json.dumps({"frames": frames}))
    out = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(out), "--masks", str(masks), "--poses", str(tmp_path / "transforms.json"),
                 "--size", "64"]) == 0
    report = capsys.readouterr().out
    assert "exposure from the photos' shared backgrounds" in report and "matched to the most exposed photo" in report, report
    assert "white balance from the photos' shared backgrounds: 10 photos" in report and "balanced as the shoot's average" in report
    capture = Capture.open(out)
    assert [e for e in capture.history if e.get("action") == "lighting"][-1]["camera_response"] == "aces"
    names = {fid: state.record.original.stem.removeprefix("shot_") for fid, state in capture.frames.items()}
    stops = capture.settings[ESTIMATED_EXPOSURE_KEY]["stops"]
    found = np.array([stops[f] for f in sorted(stops)])
    truth = np.array([-1.0 if darker[names[f]] else 0.0 for f in sorted(stops)])
    assert np.abs((found - found.mean()) - (truth - truth.mean())).max() < 0.15, (found, truth)
    balance = capture.settings[ESTIMATED_EXPOSURE_KEY]["colour_stops"]
    red_less_blue = np.array([balance[f][0] - balance[f][2] for f in sorted(stops)])
    # (red less blue: twice a channel's error; within 0.04 stops a channel, the floor on the proxy sphere)
    assert np.abs(red_less_blue - np.array([2 * tints[names[f]] for f in sorted(stops)])).max() < 0.08, red_less_blue
    # Each crop against the crop of the photo taken at one exposure and balance, in 8-bit levels: within
    # a few (the exposures are good to about 0.1 EV here, where the floor lands on the proxy sphere: no
    # support plane without COLMAP's points), where the darker photos as taken are tens of levels off.
    matched_error, unmatched_error = [], []
    for frame_id, k in names.items():
        view = capture.read_prepared(frame_id)
        mask, camera = capture.read_mask(frame_id), capture.cameras[frame_id]
        truth_view = prepare_view(frame_id, shoot.images[k], mask, camera, CropConfig(size=64))
        inside = view.mask > 0.99
        matched_error.append(np.abs(view.image_masked - truth_view.image_masked)[inside].mean() * 255)
        if darker[k]:
            as_taken = prepare_view(frame_id, capture.read_image(frame_id)[:, :, :3], mask, camera, CropConfig(size=64))
            unmatched_error.append(np.abs(as_taken.image_masked - truth_view.image_masked)[inside].mean() * 255)
    assert max(matched_error) < 8.0 and np.mean(matched_error) < 4.0, matched_error
    assert min(unmatched_error) > 15.0, unmatched_error


def test_what_the_capture_says_and_matches_by_an_estimate(lego_capture, tmp_path):
    """The three outcomes of an estimate, as the report says them and as the crops are matched: apart
    (matched), within the estimate's noise (one exposure), and pairs that disagree (not matched)."""
    import shutil

    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.capture.exposure_estimate import MAX_RESIDUAL_STOPS
    from lirm.engine.capture.exposure_match import (ESTIMATED_EXPOSURE_KEY, capture_exposure_gains, estimated_exposure_note,
                                                    white_balance_note)

    shutil.copytree(lego_capture, tmp_path / "capture")
    capture = Capture.open(tmp_path / "capture")
    assert estimated_exposure_note(capture) is None and capture_exposure_gains(capture) is None
    frames = sorted(capture.frames)
    apart = {f: (-1.0 if k % 2 else 0.0) for k, f in enumerate(frames)}
    capture.settings[ESTIMATED_EXPOSURE_KEY] = {"stops": apart, "pairs": 20, "residual_stops": 0.02, "matched": True}
    text, warn = estimated_exposure_note(capture)
    assert warn and "1.0 EV between" in text and "matched to the most exposed photo" in text
    gains = capture_exposure_gains(capture)
    assert sorted(gains) == frames
    for k, f in enumerate(frames):
        assert np.allclose(gains[f], 2.0 if k % 2 else 1.0), (f, gains[f])
    # With the balance: one photo 0.1 stops redder and less blue than the shoot, another the opposite;
    # each divided by its offset, scaled to keep a grey's luminance, times its exposure's gain.
    balance = {f: [0.0, 0.0, 0.0] for f in frames}
    balance[frames[0]], balance[frames[1]] = [0.1, 0.0, -0.1], [-0.1, 0.0, 0.1]
    capture.settings[ESTIMATED_EXPOSURE_KEY].update(colour_stops=balance, colour_matched=True)
    gains = capture_exposure_gains(capture)
    luminance = np.array([0.2126, 0.7152, 0.0722])
    assert gains[frames[0]] @ luminance == pytest.approx(1.0) and gains[frames[1]] @ luminance == pytest.approx(2.0)
    assert gains[frames[0]][2] / gains[frames[0]][0] == pytest.approx(2.0 ** 0.2)
    assert gains[frames[1]][0] / gains[frames[1]][2] == pytest.approx(2.0 ** 0.2)
    assert np.allclose(gains[frames[2]], 1.0)
    text, balanced = white_balance_note(capture)
    assert "15% apart in one colour at most" in text and "balanced as the shoot's average" in text and balanced
    capture.settings[ESTIMATED_EXPOSURE_KEY].update(colour_matched=False)
    assert np.allclose(capture_exposure_gains(capture)[frames[0]], 1.0)
    same = {f: 0.01 * k for k, f in enumerate(frames)}
    capture.settings[ESTIMATED_EXPOSURE_KEY] = {"stops": same, "pairs": 20, "residual_stops": 0.01, "matched": False}
    text, warn = estimated_exposure_note(capture)
    assert not warn and "one exposure, nothing matched" in text and capture_exposure_gains(capture) is None
    capture.settings[ESTIMATED_EXPOSURE_KEY].update(colour_stops={f: [0.01, 0.0, -0.01] for f in frames}, colour_matched=False)
    text, balanced = white_balance_note(capture)
    assert "one white balance, nothing matched" in text and not balanced
    capture.settings[ESTIMATED_EXPOSURE_KEY] = {"stops": apart, "pairs": 20, "residual_stops": 2 * MAX_RESIDUAL_STOPS,
                                                "matched": False}
    text, warn = estimated_exposure_note(capture)
    assert not warn and "disagree with each other" in text and "nothing was matched" in text
    assert capture_exposure_gains(capture) is None and white_balance_note(capture) is None
