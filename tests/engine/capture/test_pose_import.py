"""Importing poses: transforms.json (instant-ngp fox, Blender lego, nerfstudio) and COLMAP models."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at, opengl_to_opencv_c2w
from lirm.engine.capture.pose_import import (
    STATUS_NO_POSE_JSON,
    STATUS_NO_POSE_MODEL,
    import_colmap_model,
    import_transforms_json,
)
from lirm.engine.capture.records import ImageRecord, PosingResult
from lirm.engine.errors import LirmUserError


def _record(frame_id: str, original: Path, width: int, height: int) -> ImageRecord:
    # Importers only read names and sizes; the working copy need not exist.
    return ImageRecord(frame_id, Path(original), Path(f"images/{frame_id}.png"), width, height, sha256="")


# --------------------------------------------------------------------------------------------------
# transforms.json


def test_instant_ngp_fox(shared_data):
    folder = shared_data / "real_instantngp_fox"
    originals = sorted((folder / "images").glob("*.jpg"))
    records = [_record(f"{i + 1:04d}", p, 540, 960) for i, p in enumerate(originals)]
    records.append(_record("9999", folder / "images" / "not_in_the_file.jpg", 540, 960))
    res = import_transforms_json(folder / "transforms.json", records)
    assert isinstance(res, PosingResult) and res.source == "transforms.json"
    assert len(res.cameras) == len(originals) == 67
    assert res.status["9999"] == STATUS_NO_POSE_JSON
    assert all(res.status[r.frame_id] == "registered" for r in records[:-1])

    data = json.loads((folder / "transforms.json").read_text())
    frame = next(f for f in data["frames"] if f["file_path"].endswith("0012.jpg"))
    fid = next(r.frame_id for r in records if r.original.name == "0012.jpg")
    cam = res.cameras[fid]
    # Intrinsics of the 1080x1920 file, halved for the 540x960 working copy.
    assert (cam.width, cam.height) == (540, 960)
    assert cam.fx == pytest.approx(1375.52 / 2) and cam.fy == pytest.approx(1374.49 / 2)
    assert cam.cx == pytest.approx(554.558 / 2) and cam.cy == pytest.approx(965.268 / 2)
    np.testing.assert_allclose(cam.distortion, [0.0578421, -0.0805099, -0.000980296, 0.00015575])
    np.testing.assert_allclose(cam.c2w, opengl_to_opencv_c2w(np.array(frame["transform_matrix"])), atol=1e-12)


def test_blender_lego_without_extensions_or_sizes(shared_data):
    folder = shared_data / "synth_nerf_lego_train"
    names = ["r_0", "r_1", "r_10", "r_42"]
    # Working copies at half size: the file has no w/h, so its intrinsics are for the original
    # 800x800 PNGs (read from them) and are rescaled.
    records = [_record(f"{i + 1:04d}", folder / "train" / f"{n}.png", 400, 400) for i, n in enumerate(names)]
    res = import_transforms_json(folder / "transforms_train.json", records)
    assert sorted(res.cameras) == ["0001", "0002", "0003", "0004"]  # 96 other frames ignored
    data = json.loads((folder / "transforms_train.json").read_text())
    f800 = 0.5 * 800 / math.tan(0.5 * data["camera_angle_x"])
    for rec, name in zip(records, names):
        cam = res.cameras[rec.frame_id]
        assert cam.fx == pytest.approx(f800 / 2) and cam.cx == pytest.approx(200.0)
        assert cam.distortion is None
        frame = next(f for f in data["frames"] if f["file_path"] == f"./train/{name}")
        np.testing.assert_allclose(cam.c2w, opengl_to_opencv_c2w(np.array(frame["transform_matrix"])))
        # Blender cameras orbit the object at the origin: the OpenCV +z must look at it.
        assert float(np.dot(cam.forward, -cam.center / np.linalg.norm(cam.center))) > 0.95


def test_field_of_view_file_needs_no_original(tmp_path):
    c2w = np.eye(4)
    c2w[2, 3] = 4.0
    (tmp_path / "t.json").write_text(json.dumps(
        {"camera_angle_x": math.radians(60), "frames": [{"file_path": "shots/a", "transform_matrix": c2w.tolist()}]}
    ))
    res = import_transforms_json(tmp_path / "t.json", [_record("0001", tmp_path / "gone" / "a.jpg", 300, 200)])
    cam = res.cameras["0001"]
    assert cam.fov_x_deg == pytest.approx(60.0) and (cam.cx, cam.cy) == (150.0, 100.0)


def _nerfstudio_cameras() -> list[Camera]:
    cams = []
    for k in range(3):
        eye = [3 * math.cos(k), 3 * math.sin(k), 1.0]
        cams.append(Camera(640, 480, 500 + k, 505 + k, 322.5, 238.0, look_at(eye, [0, 0, 0]),
                           [0.01 * k, -0.02, 0.001, 0.0005]))
    return cams


def test_nerfstudio_per_frame_intrinsics(tmp_path):
    cams = _nerfstudio_cameras()
    frames = [{**c.to_dict(), "file_path": f"images/frame_{k + 1:05d}.png"} for k, c in enumerate(cams)]
    (tmp_path / "transforms.json").write_text(json.dumps({"camera_model": "OPENCV", "frames": frames}))
    # Originals were JPEGs named like the frames; the working copies are half size.
    records = [_record(f"{k + 1:04d}", tmp_path / f"frame_{k + 1:05d}.JPG", 320, 240) for k in range(3)]
    res = import_transforms_json(tmp_path / "transforms.json", records)
    for rec, cam in zip(records, cams):
        assert res.cameras[rec.frame_id].allclose(cam.resized(320, 240), atol=1e-9)


def test_nerfstudio_top_level_intrinsics(tmp_path):
    cams = _nerfstudio_cameras()
    top = {k: v for k, v in cams[0].to_dict().items() if k != "transform_matrix"}
    frames = [{"file_path": f"images/{k}.png", "transform_matrix": c.to_dict()["transform_matrix"]}
              for k, c in enumerate(cams)]
    (tmp_path / "transforms.json").write_text(json.dumps({**top, "aabb_scale": 16, "scale": 0.3,
                                                          "offset": [0.5, 0.5, 0.5], "frames": frames}))
    records = [_record(f"{k:04d}", tmp_path / f"{k}.png", 640, 480) for k in range(3)]
    res = import_transforms_json(tmp_path / "transforms.json", records)
    for rec, cam in zip(records, cams):
        got = res.cameras[rec.frame_id]
        assert got.allclose(cams[0].with_pose(cam.c2w), atol=1e-9)


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "not valid JSON"),
        (json.dumps({"camera_angle_x": 0.7}), "no 'frames'"),
        (json.dumps({"camera_angle_x": 0.7, "frames": [{"file_path": "a.png"}]}), "transform_matrix"),
        (json.dumps({"frames": [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}]}), "focal"),
        (json.dumps({"camera_angle_x": 0.7, "frames": [{"file_path": "a.png",
                                                          "transform_matrix": (2 * np.eye(4)).tolist()}]}), "rigid"),
        (json.dumps({"camera_model": "OPENCV_FISHEYE", "fl_x": 100, "w": 10, "h": 10,
                     "frames": [{"file_path": "a.png", "transform_matrix": np.eye(4).tolist()}]}), "not supported"),
    ],
)
def test_bad_transforms_files(tmp_path, content, message):
    p = tmp_path / "transforms.json"
    p.write_text(content)
    with pytest.raises(LirmUserError, match=message) as err:
        import_transforms_json(p, [_record("0001", tmp_path / "a.png", 10, 10)])
    assert str(p) in str(err.value)


def test_missing_transforms_file(tmp_path):
    with pytest.raises(LirmUserError, match="not found"):
        import_transforms_json(tmp_path / "nope.json", [])


# --------------------------------------------------------------------------------------------------
# COLMAP models


@pytest.fixture(scope="module")
def synthetic_model():
    pycolmap = pytest.importorskip("pycolmap")
    opts = pycolmap.SyntheticDatasetOptions(
        num_rigs=1, num_cameras_per_rig=1, num_frames_per_rig=6, num_points3D=60,
        camera_model_id=pycolmap.CameraModelId.OPENCV,
        camera_params=[500.0, 510.0, 321.0, 242.0, 0.05, -0.02, 0.001, 0.002],
        camera_width=640, camera_height=480,
    )
    pycolmap.set_random_seed(0)
    return pycolmap.synthesize_dataset(opts)


@pytest.mark.parametrize("fmt", ["text", "binary"])
def test_colmap_model_round_trip(tmp_path, synthetic_model, fmt):
    rec = synthetic_model
    (tmp_path / "m").mkdir()
    getattr(rec, f"write_{fmt}")(str(tmp_path / "m"))
    names = sorted(im.name for im in rec.images.values())
    # Half-size working copies; one image missing from the model.
    records = [_record(f"{k + 1:04d}", tmp_path / n, 320, 240) for k, n in enumerate(names)]
    records.append(_record("0099", tmp_path / "other.png", 320, 240))
    res = import_colmap_model(tmp_path / "m", records)
    assert res.source == "colmap-model"
    assert len(res.cameras) == len(names) == 6
    assert res.status["0099"] == STATUS_NO_POSE_MODEL
    assert res.points.shape == (rec.num_points3D(), 3) and res.point_colors.dtype == np.uint8
    # Every observation reprojects onto its keypoint (scaled by 1/2): pose, pixel convention and
    # OpenCV distortion agree with COLMAP's.
    by_name = {r.original.name: r.frame_id for r in records}
    pid_index = {pid: k for k, pid in enumerate(sorted(rec.point3D_ids()))}
    worst = 0.0
    for im in rec.images.values():
        cam = res.cameras[by_name[im.name]]
        obs = im.get_observation_points2D()
        xyz = res.points[[pid_index[p.point3D_id] for p in obs]]
        uv, depth = cam.project(xyz)
        assert np.all(depth > 0)
        worst = max(worst, float(np.abs(uv - np.array([np.asarray(p.xy).ravel() for p in obs]) / 2).max()))
        assert set(res.observations[by_name[im.name]]) == {pid_index[p.point3D_id] for p in obs}
    assert worst < 1e-6


def test_hand_written_text_model(tmp_path):
    m = tmp_path / "sparse" / "0"
    m.mkdir(parents=True)
    (m / "cameras.txt").write_text("# comment\n1 PINHOLE 200 100 150 160 101 49\n2 SIMPLE_RADIAL 200 100 150 100 50 0.1\n")
    # qw qx qy qz = identity, t = (0, 0, 5): the camera sits at (0, 0, -5) looking along +z.
    (m / "images.txt").write_text(
        "1 1 0 0 0 0 0 5 1 a.jpg\n\n"
        "2 0 0 1 0 0 0 5 2 b.jpg\n\n"  # rotated 180 degrees about y
    )
    (m / "points3D.txt").write_text("")
    records = [_record("0001", tmp_path / "a.jpg", 200, 100), _record("0002", tmp_path / "b.jpg", 400, 200)]
    res = import_colmap_model(m, records)
    a, b = res.cameras["0001"], res.cameras["0002"]
    assert (a.fx, a.fy, a.cx, a.cy) == (150, 160, 101, 49) and a.distortion is None
    np.testing.assert_allclose(a.center, [0, 0, -5], atol=1e-12)
    np.testing.assert_allclose(a.forward, [0, 0, 1], atol=1e-12)
    assert (b.width, b.fx, b.cx) == (400, 300, 200)
    np.testing.assert_allclose(b.distortion, [0.1, 0, 0, 0])
    np.testing.assert_allclose(b.center, [0, 0, 5], atol=1e-12)
    np.testing.assert_allclose(b.forward, [0, 0, -1], atol=1e-12)
    # A parent folder is refused with a hint at the model inside it.
    with pytest.raises(LirmUserError, match="did you mean"):
        import_colmap_model(tmp_path / "sparse", records)


def test_bad_colmap_models(tmp_path):
    with pytest.raises(LirmUserError, match="not a folder"):
        import_colmap_model(tmp_path / "missing", [])
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "cameras.txt").write_text("1 PINHOLE 10 10 5 5 5 5\n")
    with pytest.raises(LirmUserError, match="images.bin/.txt"):
        import_colmap_model(tmp_path / "m", [])
    (tmp_path / "m" / "images.txt").write_text("")
    (tmp_path / "m" / "points3D.txt").write_text("")
    (tmp_path / "m" / "cameras.txt").write_text("1 PINHOLE ten 10 5 5 5 5\n")
    with pytest.raises(LirmUserError, match="cannot read the COLMAP model"):
        import_colmap_model(tmp_path / "m", [])
    (tmp_path / "m" / "cameras.txt").write_text("1 OPENCV_FISHEYE 10 10 5 5 5 5 0 0 0 0\n")
    (tmp_path / "m" / "images.txt").write_text("1 1 0 0 0 0 0 5 1 a.jpg\n\n")
    with pytest.raises(LirmUserError, match="fisheye"):
        import_colmap_model(tmp_path / "m", [_record("0001", tmp_path / "a.jpg", 10, 10)])
