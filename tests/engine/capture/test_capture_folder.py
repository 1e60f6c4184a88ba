"""The capture folder round-trips through its files and refuses what is not a capture."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at
from lirm.engine.capture.capture_folder import Capture, FrameState
from lirm.engine.capture.crop import CropConfig, prepare_view
from lirm.engine.capture.normalize import estimate_normalization
from lirm.engine.capture.records import FileReport, ImageRecord
from lirm.engine.errors import LirmUserError
from lirm.engine.io.images import write_png


def _capture(tmp_path: Path) -> Capture:
    capture = Capture.create(tmp_path / "cap", settings={"max_side": 640})
    for i in range(3):
        fid = f"{i + 1:04d}"
        image = np.full((48, 64, 3), 40 * i, np.uint8)
        write_png(capture.root / "images" / f"{fid}.png", image)
        record = ImageRecord(fid, Path(f"/photos/{fid}.jpg"), Path(f"images/{fid}.png"), 64, 48, "ab" * 32)
        capture.frames[fid] = FrameState(record, pose_status="registered")
        capture.cameras[fid] = Camera.from_fov(64, 48, 50.0, look_at((np.sin(i), -3.0, 0.5), (0, 0, 0)))
    capture.normalization = estimate_normalization(capture.cameras)
    capture.points = np.random.default_rng(0).normal(size=(10, 3))
    capture.observations = {"0001": np.array([0, 3, 7]), "0002": np.array([1, 3])}
    capture.reports.append(FileReport(Path("/photos/bad.jpg"), False, "not a JPEG"))
    capture.log("posed", registered=3)
    return capture


def test_save_and_reopen(tmp_path):
    capture = _capture(tmp_path)
    mask = np.zeros((48, 64), np.uint8)
    mask[10:30, 20:40] = 255
    capture.write_mask("0002", mask, source="auto", status="ok")
    capture.save()
    again = Capture.open(capture.root)
    assert sorted(again.frames) == ["0001", "0002", "0003"]
    assert again.frames["0002"].mask_source == "auto"
    assert again.cameras["0003"].allclose(capture.cameras["0003"])
    np.testing.assert_allclose(again.normalization.world_from_source, capture.normalization.world_from_source)
    np.testing.assert_allclose(again.points, capture.points)
    assert sorted(again.observations) == ["0001", "0002"]
    np.testing.assert_array_equal(again.observations["0001"], [0, 3, 7])
    assert again.reports[0].reason == "not a JPEG"
    assert [h["action"] for h in again.history] == ["created", "posed"]
    np.testing.assert_array_equal(again.read_mask("0002"), mask)
    transforms = json.loads((capture.root / "transforms.json").read_text())
    assert len(transforms["frames"]) == 3
    assert transforms["frames"][1]["mask_path"] == "masks/0002.png"
    assert Camera.from_dict({**transforms, **transforms["frames"][0]}).allclose(capture.cameras["0001"], atol=1e-9)


def test_prepared_views_round_trip_exactly(tmp_path):
    capture = _capture(tmp_path)
    mask = np.zeros((48, 64), np.uint8)
    mask[10:30, 20:40] = 255
    view = prepare_view("0001", capture.read_image("0001"), mask, capture.cameras["0001"], CropConfig(size=32))
    capture.write_prepared(view)
    back = capture.read_prepared("0001")
    for name in ("image_masked", "image_bg", "mask", "plucker"):
        np.testing.assert_array_equal(getattr(back, name), getattr(view, name))
    assert back.crop_box == view.crop_box and back.camera.allclose(view.camera)
    assert capture.read_prepared("0002") is None


def test_refuses_non_captures_and_occupied_folders(tmp_path):
    with pytest.raises(LirmUserError, match="not a capture"):
        Capture.open(tmp_path)
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.jpg").write_bytes(b"x")
    with pytest.raises(LirmUserError, match="not empty"):
        Capture.create(tmp_path / "photos")
    capture = _capture(tmp_path)
    capture.save()
    with pytest.raises(LirmUserError, match="--resume"):  # its stages never ran: an interrupted capture
        Capture.create(capture.root)
    capture.settings["completed"] = ["pose", "normalize", "masks", "crops"]
    capture.save()
    with pytest.raises(LirmUserError, match="--add"):
        Capture.create(capture.root)
    (capture.root / "capture.json").write_text("{ broken")
    with pytest.raises(LirmUserError, match="damaged"):
        Capture.open(capture.root)
