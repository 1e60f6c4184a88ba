"""Views placed on the wrong side of the object are found by their outlines.

The NeRF lego's renders with their true cameras and alpha outlines; some cameras are then turned a
quarter circle about the vertical axis through the object: each looks at the object from another
side while its photo still shows the first, as when structure from motion registers a view with
matches to a part that looks alike elsewhere on the object.

What the check cannot see: a view turned half a circle about the lego's middle has nearly the
outline it had (the lego is long and low, its outline nearly the same from front and back), so such
a view is kept. It then also does little harm to the shape carved from the outlines.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from lirm.engine.cameras import Camera
from lirm.engine.capture.masks import mask_from_alpha
from lirm.engine.capture.pose_silhouettes import PoseSilhouetteConfig, views_against_silhouettes

LEGO_VIEWS = list(range(1, 100, 4))  # 25 of the 100 renders, all around the object
LEGO_RADIUS = 1.5
QUARTER_TURN = np.array([[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]])  # about +Z, the scene's up


@pytest.fixture(scope="module")
def lego(shared_data):
    lego = shared_data / "synth_nerf_lego_train"
    if not (lego / "transforms_train.json").is_file():
        pytest.skip(f"lego renders missing under {shared_data}")
    meta = json.loads((lego / "transforms_train.json").read_text())
    outlines, cameras = {}, {}
    for i in LEGO_VIEWS:
        frame = meta["frames"][i]
        bgra = cv2.imread(str(lego / (frame["file_path"].removeprefix("./") + ".png")), cv2.IMREAD_UNCHANGED)
        h, w = bgra.shape[:2]
        # Half size: the check carves at 64 voxels a side, far coarser than the photos.
        small = cv2.resize(bgra, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        fid = f"{i:04d}"
        outlines[fid] = mask_from_alpha(small[:, :, [2, 1, 0, 3]])
        cameras[fid] = Camera.from_nerf(np.array(frame["transform_matrix"]), meta["camera_angle_x"], w // 2, h // 2)
    return outlines, cameras


def _turned(cameras: dict[str, Camera], frames: list[str]) -> dict[str, Camera]:
    return {f: (c.moved_by(QUARTER_TURN) if f in frames else c) for f, c in cameras.items()}


def test_right_poses_leave_out_nothing(lego):
    outlines, cameras = lego
    assert views_against_silhouettes(outlines, cameras, LEGO_RADIUS) == {}


def test_views_turned_to_another_side_are_left_out(lego):
    outlines, cameras = lego
    wrong = [sorted(outlines)[k] for k in (2, 7, 13, 21)]
    left_out = views_against_silhouettes(outlines, _turned(cameras, wrong), LEGO_RADIUS)
    assert sorted(left_out) == sorted(wrong), left_out
    assert all(share > PoseSilhouetteConfig().max_outside for share in left_out.values())


def test_without_a_majority_nothing_is_left_out(lego):
    """13 of 25 views turned: which side is right cannot be told, so no view is left out."""
    outlines, cameras = lego
    wrong = sorted(outlines)[::2]
    assert views_against_silhouettes(outlines, _turned(cameras, wrong), LEGO_RADIUS) == {}


def test_the_check_can_be_turned_off_and_needs_five_views(lego):
    outlines, cameras = lego
    wrong = [sorted(outlines)[2]]
    turned = _turned(cameras, wrong)
    assert views_against_silhouettes(outlines, turned, LEGO_RADIUS, PoseSilhouetteConfig(enabled=False)) == {}
    four = {f: outlines[f] for f in sorted(outlines)[:4]}
    assert views_against_silhouettes(four, turned, LEGO_RADIUS) == {}


def test_a_capture_unposes_the_views_whose_pose_disagrees_with_the_outlines(tmp_path, shared_data):
    """Through the capture's normalisation: the lego's RGBA renders posed by their own transforms, then
    four of their cameras turned as if COLMAP had placed them; normalising again leaves those four
    out (unposed, with the reason in their status) and keeps the rest."""
    import shutil
    from dataclasses import replace

    from lirm.engine.capture import pipeline
    from lirm.engine.capture.ingest import IngestConfig

    lego = shared_data / "synth_nerf_lego_train"
    meta = json.loads((lego / "transforms_train.json").read_text())
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in LEGO_VIEWS:
        name = meta["frames"][i]["file_path"].removeprefix("./") + ".png"
        shutil.copy(lego / name, photos / name.split("/")[-1])
    config = pipeline.CaptureConfig(poses=str(lego / "transforms_train.json"), masks="alpha",
                                    ingest=replace(IngestConfig(), max_side=400))
    capture = pipeline.run_capture(photos, tmp_path / "capture", config).capture
    assert len(capture.cameras) == len(LEGO_VIEWS)
    frames = sorted(capture.cameras)
    wrong = [frames[k] for k in (2, 7, 13, 21)]
    capture.settings["pose_source"] = "colmap"  # as if structure from motion had posed them
    turned = {f: Camera.from_dict(capture.settings["source_cameras"][f]).moved_by(QUARTER_TURN).to_dict() for f in wrong}
    capture.settings["source_cameras"].update(turned)
    pipeline._normalize(capture, config)
    left_out = sorted(f for f, state in capture.frames.items() if state.pose_status.startswith(pipeline.LEFT_OUT))
    assert left_out == sorted(wrong)
    assert sorted(capture.cameras) == sorted(set(frames) - set(wrong))
    assert all(f not in capture.settings["source_cameras"] for f in wrong)

    # The user's own poses are taken as given, wrong or not.
    capture.settings["pose_source"] = "transforms.json"
    capture.settings["source_cameras"].update(turned)
    for f in wrong:
        capture.frames[f].pose_status = "registered"
    pipeline._normalize(capture, config)
    assert sorted(capture.cameras) == frames
