"""COLMAP posing on real photos (fox, cake, lego) and the COLMAP -> Camera conventions."""

from __future__ import annotations

import shutil
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from lirm.engine.capture.alignment import pose_errors
from lirm.engine.capture.colmap_posing import (
    STATUS_NO_FEATURES,
    STATUS_NO_MATCHES,
    STATUS_NO_START,
    STATUS_NOT_REGISTERED,
    STATUS_REGISTERED,
    STATUS_SEPARATE_MODEL,
    SUPPORTED_CAMERA_MODELS,
    Cancelled,
    ColmapConfig,
    camera_from_colmap,
    extend_colmap_pose,
    map_again_without,
    intrinsics_from_colmap,
    pose_with_colmap,
    read_colmap_work_dir,
)
from lirm.engine.capture.pose_import import import_transforms_json
from lirm.engine.capture.records import ImageRecord, PosingResult
from lirm.engine.errors import LirmUserError

pycolmap = pytest.importorskip("pycolmap")
cv2 = pytest.importorskip("cv2")

FOX_FOCAL_FULL = 1375.5  # the capture's calibrated focal length at 1080x1920
REASONS = {STATUS_NO_FEATURES, STATUS_NO_MATCHES, STATUS_NOT_REGISTERED, STATUS_SEPARATE_MODEL, STATUS_NO_START}


def _make_records(sources: list[Path], root: Path, long_side: int | None, first: int = 1) -> list[ImageRecord]:
    """Working copies as ingest makes them: RGB JPEGs (alpha composited on black), long side capped,
    in root/images named by frame id. The originals are only read."""
    (root / "images").mkdir(parents=True, exist_ok=True)
    records = []
    for k, src in enumerate(sources):
        im = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
        if im.ndim == 3 and im.shape[2] == 4:
            alpha = im[..., 3:].astype(np.float32) / 255.0
            im = np.round(im[..., :3] * alpha).astype(np.uint8)
        h, w = im.shape[:2]
        if long_side is not None and max(h, w) != long_side:
            s = long_side / max(h, w)
            im = cv2.resize(im, (round(w * s), round(h * s)), interpolation=cv2.INTER_AREA)
        fid = f"{first + k:04d}"
        cv2.imwrite(str(root / "images" / f"{fid}.jpg"), im, [cv2.IMWRITE_JPEG_QUALITY, 95])
        records.append(ImageRecord(fid, Path(src), Path(f"images/{fid}.jpg"), im.shape[1], im.shape[0], sha256=""))
    return records


def _fox_photos(shared_data: Path) -> list[Path]:
    return sorted((shared_data / "real_instantngp_fox" / "images").glob("*.jpg"))


@pytest.fixture(scope="module")
def fox20(shared_data, tmp_path_factory):
    """20 fox photos at 960 px posed once for the module (~20-60 s on 2 cores)."""
    root = tmp_path_factory.mktemp("fox20")
    records = _make_records(_fox_photos(shared_data)[:20], root, 960)
    stages = []
    t0 = time.perf_counter()
    result = pose_with_colmap(records, root, root / "colmap", progress=lambda *a: stages.append(a))
    seconds = time.perf_counter() - t0
    print(f"\nfox: {len(result.cameras)}/20 registered in {seconds:.1f} s, {len(result.points)} points")
    return SimpleNamespace(root=root, records=records, result=result, seconds=seconds, stages=stages)


@pytest.mark.slow
def test_fox_all_photos_register(fox20):
    res = fox20.result
    assert isinstance(res, PosingResult) and res.source == "colmap"
    assert res.registered == [r.frame_id for r in fox20.records]
    assert set(res.status.values()) == {STATUS_REGISTERED}
    # One camera for the set: identical intrinsics everywhere, sized like the working copies.
    cams = list(res.cameras.values())
    assert all((c.width, c.height) == (540, 960) for c in cams)
    assert len({(c.fx, c.cx, c.cy) for c in cams}) == 1
    # Progress went through every stage and ended with everything registered.
    assert [s for s, *_ in fox20.stages][:1] == ["extract"] and {"match", "map"} <= {s for s, *_ in fox20.stages}
    assert fox20.stages[-1] == ("map", 20, 20)


@pytest.mark.slow
def test_fox_poses_match_the_capture_calibration(fox20, shared_data):
    ref = import_transforms_json(shared_data / "real_instantngp_fox" / "transforms.json", fox20.records)
    assert len(ref.cameras) == 20
    e = pose_errors(fox20.result.cameras, ref.cameras)
    centres_only = pose_errors(fox20.result.cameras, ref.cameras, align="centers")
    fx = fox20.result.cameras["0001"].fx
    expected_fx = FOX_FOCAL_FULL * 960 / 1920
    print(
        f"\nfox vs transforms.json: rotation median {e['rotation_deg_median']:.3f} max {e['rotation_deg_max']:.3f} deg; "
        f"centre median {100 * e['center_error_median']:.3f} % max {100 * e['center_error_max']:.3f} % "
        f"(centres-only alignment: rotation max {centres_only['rotation_deg_max']:.3f} deg, centre max "
        f"{100 * centres_only['center_error_max']:.3f} %); fx {fx:.2f} vs {expected_fx:.2f} "
        f"({100 * (fx / expected_fx - 1):+.2f} %); {fox20.seconds:.1f} s"
    )
    assert e["rotation_deg_max"] < 1.0
    assert e["center_error_median"] < 0.01
    assert centres_only["center_error_max"] < 0.01
    assert fx == pytest.approx(expected_fx, rel=0.02)
    assert e["focal_ratio"] == pytest.approx(1.0, abs=0.02)


@pytest.mark.slow
def test_fox_sparse_points_are_seen_by_their_cameras(fox20):
    res = fox20.result
    assert res.points.shape[0] > 1000 and res.points.shape == res.point_colors.shape
    assert res.point_colors.dtype == np.uint8 and res.point_colors.max() > 0
    for fid, cam in res.cameras.items():
        idx = res.observations[fid]
        assert len(idx) > 100 and idx.max() < len(res.points)
        uv, depth = cam.project(res.points[idx])
        inside = (depth > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam.height)
        assert inside.mean() > 0.99


@pytest.mark.slow
def test_fox_work_folder_reads_back(fox20):
    again = read_colmap_work_dir(fox20.root / "colmap")
    assert again.registered == fox20.result.registered
    assert again.status == fox20.result.status
    for fid, cam in fox20.result.cameras.items():
        assert again.cameras[fid].allclose(cam, atol=1e-9)


@pytest.mark.slow
def test_extend_registers_added_photos_without_moving_the_others(fox20, shared_data, tmp_path):
    work = tmp_path / "colmap"
    shutil.copytree(fox20.root / "colmap", work)
    new = _make_records(_fox_photos(shared_data)[20:23], fox20.root, 960, first=21)
    t0 = time.perf_counter()
    res = extend_colmap_pose(work, new, fox20.root)
    print(f"\nextend: {len(res.cameras)}/23 registered in {time.perf_counter() - t0:.1f} s")
    assert res.registered == [f"{i:04d}" for i in range(1, 24)]
    for fid, cam in fox20.result.cameras.items():
        assert res.cameras[fid].allclose(cam, atol=1e-9)  # existing frames and intrinsics held fixed
    assert res.cameras["0023"].fx == fox20.result.cameras["0001"].fx
    # The added cameras sit where the capture's own calibration puts them.
    ref = import_transforms_json(shared_data / "real_instantngp_fox" / "transforms.json", fox20.records + new)
    e = pose_errors(res.cameras, ref.cameras)
    assert max(e["rotation_deg"][f] for f in ("0021", "0022", "0023")) < 1.0
    # Adding the same photos again changes nothing.
    assert extend_colmap_pose(work, new, fox20.root).registered == res.registered


@pytest.mark.slow
def test_mapping_again_without_some_views(fox20, shared_data, tmp_path):
    """The views left out are no longer posed; the rest are, where the capture's calibration puts
    them, from the matches already in the database (no extraction or matching again)."""
    work = tmp_path / "colmap"
    shutil.copytree(fox20.root / "colmap", work)
    t0 = time.perf_counter()
    res = map_again_without(work, ["0004", "0011"], fox20.records)
    print(f"\nmapped again without 2 views: {len(res.cameras)}/18 registered in {time.perf_counter() - t0:.1f} s")
    assert res.registered == [r.frame_id for r in fox20.records if r.frame_id not in ("0004", "0011")]
    assert res.status["0004"] != STATUS_REGISTERED and res.status["0011"] != STATUS_REGISTERED
    ref = import_transforms_json(shared_data / "real_instantngp_fox" / "transforms.json", fox20.records)
    e = pose_errors(res.cameras, ref.cameras)
    assert e["rotation_deg_max"] < 1.0 and e["center_error_median"] < 0.01
    # The saved model is the new one: reading the folder back gives the same posing.
    assert read_colmap_work_dir(work).registered == res.registered
    assert all(max(idx) < len(res.points) for idx in res.observations.values())


def test_unrelated_photos_get_a_reason(shared_data, tmp_path):
    fox = _fox_photos(shared_data)[0:8:2]
    lego = [shared_data / "synth_nerf_lego_train" / "train" / f"r_{i}.png" for i in (0, 1, 2)]
    records = _make_records(fox, tmp_path, 480) + _make_records(lego, tmp_path, 480, first=5)
    res = pose_with_colmap(records, tmp_path, tmp_path / "colmap")
    print("\nfox + lego:", res.status)
    assert res.registered == ["0001", "0002", "0003", "0004"]
    assert set(res.status) == {r.frame_id for r in records}
    for fid in ("0005", "0006", "0007"):
        assert res.status[fid] in REASONS
    # Two image sizes: one camera each; the fox camera is the one used.
    assert {(c.width, c.height) for c in res.cameras.values()} == {(270, 480)}


def test_cake_hard_case(shared_data, tmp_path):
    """8 video frames of a cake slice (683x384, small baseline). Measured with the defaults: nothing
    registers. Pairs 5-6 and 7-8 verify with ~500 inliers but no pair has the viewpoint change
    COLMAP needs to start a model (STATUS_NO_START for frames 2-8); frame 1 matches nothing."""
    src = sorted((shared_data / "real_vggsfm_cake" / "images").glob("*.jpg"))
    records = _make_records(src, tmp_path, None)
    res = pose_with_colmap(records, tmp_path, tmp_path / "colmap")
    print(f"\ncake: {len(res.cameras)}/8 registered:", res.status)
    assert isinstance(res, PosingResult)
    assert set(res.status) == {r.frame_id for r in records}
    assert all(s == STATUS_REGISTERED or s in REASONS for s in res.status.values())
    assert set(res.cameras) == {f for f, s in res.status.items() if s == STATUS_REGISTERED}


def test_sequential_matching_and_per_image_cameras(shared_data, tmp_path):
    records = _make_records(_fox_photos(shared_data)[:8], tmp_path, 400)
    cfg = ColmapConfig(matcher="sequential", sequential_overlap=3, single_camera=False, camera_model="PINHOLE")
    res = pose_with_colmap(records, tmp_path, tmp_path / "colmap", cfg)
    assert res.registered == [r.frame_id for r in records]
    assert len({c.fx for c in res.cameras.values()}) == 8  # one camera each
    expected = FOX_FOCAL_FULL * 400 / 1920
    assert all(c.fx == pytest.approx(expected, rel=0.05) and c.distortion is None for c in res.cameras.values())
    with pycolmap.Database.open(str(tmp_path / "colmap" / "database.db")) as db:
        ids = {Path(im.name).stem: im.image_id for im in db.read_all_images()}
        assert db.exists_matches(ids["0001"], ids["0002"])
        assert not db.exists_matches(ids["0001"], ids["0008"])  # beyond the overlap: never tried


def test_cancel(shared_data, tmp_path):
    records = _make_records(_fox_photos(shared_data)[:3], tmp_path, 320)
    with pytest.raises(Cancelled):
        pose_with_colmap(records, tmp_path, tmp_path / "a", cancel=lambda: True)
    stop = threading.Event()

    def progress(stage, done, total):
        if stage == "match":
            stop.set()

    with pytest.raises(Cancelled):
        pose_with_colmap(records, tmp_path, tmp_path / "b", progress=progress, cancel=stop.is_set)


def test_setup_problems_raise_user_errors(tmp_path):
    rec = ImageRecord("0001", tmp_path / "a.jpg", Path("images/0001.jpg"), 10, 10, sha256="")
    with pytest.raises(LirmUserError, match="no images"):
        pose_with_colmap([], tmp_path, tmp_path / "w")
    with pytest.raises(LirmUserError, match="missing"):
        pose_with_colmap([rec], tmp_path, tmp_path / "w")
    with pytest.raises(LirmUserError, match="twice"):
        pose_with_colmap([rec, rec], tmp_path, tmp_path / "w")
    with pytest.raises(LirmUserError, match="fisheye"):
        pose_with_colmap([rec], tmp_path, tmp_path / "w", ColmapConfig(camera_model="OPENCV_FISHEYE"))
    with pytest.raises(LirmUserError, match="matcher"):
        pose_with_colmap([rec], tmp_path, tmp_path / "w", ColmapConfig(matcher="vocab"))
    with pytest.raises(LirmUserError, match="not a COLMAP posing folder"):
        extend_colmap_pose(tmp_path / "nothing", [rec], tmp_path)


# --------------------------------------------------------------------------------------------------
# Conventions: our Camera projects exactly like COLMAP for every supported model


_PARAMS = {
    "SIMPLE_PINHOLE": [400.0, 161.0, 119.5],
    "PINHOLE": [400.0, 390.0, 161.0, 119.5],
    "SIMPLE_RADIAL": [400.0, 161.0, 119.5, -0.08],
    "RADIAL": [400.0, 161.0, 119.5, -0.08, 0.02],
    "OPENCV": [400.0, 390.0, 161.0, 119.5, -0.08, 0.02, 0.001, -0.002],
    "FULL_OPENCV": [400.0, 390.0, 161.0, 119.5, -0.08, 0.02, 0.001, -0.002, 0.003, 0.01, -0.004, 0.002],
}


@pytest.mark.parametrize("model", SUPPORTED_CAMERA_MODELS)
def test_colmap_camera_models_project_like_colmap(model):
    rng = np.random.default_rng(0)
    cam = pycolmap.Camera.create_from_model_name(1, model, 400.0, 320, 240)
    cam.params = _PARAMS[model]
    q = rng.normal(size=4)
    cam_from_world = pycolmap.Rigid3d(pycolmap.Rotation3d(q / np.linalg.norm(q)), rng.normal(size=3))
    ours = camera_from_colmap(cam, cam_from_world.matrix())
    # World points in front of the camera, across the image.
    p_cam = np.column_stack([rng.uniform(-0.35, 0.35, 200), rng.uniform(-0.3, 0.3, 200), np.ones(200)])
    p_cam *= rng.uniform(1, 5, size=(200, 1))
    p_world = cam_from_world.inverse() * p_cam
    uv, depth = ours.project(p_world)
    np.testing.assert_allclose(uv, cam.img_from_cam(p_cam), atol=1e-9)
    np.testing.assert_allclose(depth, p_cam[:, 2], atol=1e-9)


def test_fisheye_models_are_refused():
    for model in ("OPENCV_FISHEYE", "SIMPLE_RADIAL_FISHEYE", "FOV", "THIN_PRISM_FISHEYE"):
        with pytest.raises(ValueError, match="fisheye"):
            intrinsics_from_colmap(model, [1.0] * 4)
