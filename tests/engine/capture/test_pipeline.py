"""The capture pipeline end to end through `lirm capture`: real photos, bad input, imported poses,
adding photos, and resuming an interrupted capture."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from lirm.engine.assets.environment_files import resolve_environment
from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.report import format_capture_report
from lirm.engine.capture.visual_hull import carve_visual_hull, sphere_silhouette
from lirm.engine.capture.pipeline import CaptureConfig, resume_capture, run_capture
from lirm.engine.cli import main
from lirm.engine.errors import EnvironmentLoadError


def _hashes(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _fox(shared_data: Path, n: int, start: int = 0) -> list[Path]:
    return sorted((shared_data / "real_instantngp_fox" / "images").glob("*.jpg"))[start:start + n]


@pytest.fixture(scope="module")
def messy_folder(tmp_path_factory, shared_data) -> Path:
    """10 fox photos + 3 cake frames (an unrelated object) + a corrupt JPEG, a text file named .jpg,
    a 1x1 image and a byte-identical duplicate."""
    folder = tmp_path_factory.mktemp("messy")
    for p in _fox(shared_data, 10, start=0):
        shutil.copy(p, folder / p.name)
    for p in sorted((shared_data / "real_vggsfm_cake" / "images").glob("*.jpg"))[:3]:
        if p.suffix.lower() in (".jpg", ".png"):
            shutil.copy(p, folder / f"cake_{p.name}")
    data = _fox(shared_data, 1, start=20)[0].read_bytes()
    (folder / "corrupt.jpg").write_bytes(data[: len(data) // 3])
    (folder / "notes.jpg").write_text("this is not a photo")
    cv2.imwrite(str(folder / "tiny.png"), np.zeros((1, 1, 3), np.uint8))
    shutil.copy(folder / _fox(shared_data, 1)[0].name, folder / "copy_of_first.jpg")
    return folder


@pytest.mark.slow
def test_messy_folder_gives_a_report_and_a_usable_capture(messy_folder, tmp_path, capsys):
    before = _hashes(messy_folder)
    out = tmp_path / "capture"
    code = main(["capture", str(messy_folder), "-o", str(out), "--max-side", "640", "--masks", "automatic", "--size", "64"])
    report = capsys.readouterr().out
    assert code == 0, report
    assert _hashes(messy_folder) == before  # the user's folder is byte-for-byte unchanged
    for name in ("corrupt.jpg", "notes.jpg", "tiny.png", "copy_of_first.jpg"):
        assert f"skipped {name}" in report, report
    capture = Capture.open(out)
    fox_ids = [f for f, s in capture.frames.items() if not s.record.original.name.startswith("cake")]
    cake_ids = [f for f, s in capture.frames.items() if s.record.original.name.startswith("cake")]
    assert len(fox_ids) == 10 and cake_ids
    assert sum(capture.frames[f].pose_status == "registered" for f in fox_ids) >= 9
    for f in cake_ids:  # the unrelated object is reported, not silently dropped
        assert capture.frames[f].pose_status != "registered"
        assert capture.frames[f].record.original.name in report
    # Automatic masks on the fox (a wall trophy in front of busy wallpaper) may take in some
    # wallpaper; every view without a prepared crop must then be named in the report with why.
    prepared = {p.stem for p in (out / "prepared").glob("*.npz")}
    for f in fox_ids:
        if capture.frames[f].pose_status == "registered" and f not in prepared:
            assert capture.frames[f].mask_status != "ok" and f"({f}): mask" in report, report
    transforms = json.loads((out / "transforms.json").read_text())
    assert len(transforms["frames"]) == len(capture.cameras)
    # Normalised: cameras around the origin, +Z roughly their average up.
    ups = np.mean([c.up for c in capture.cameras.values()], axis=0)
    assert ups[2] / np.linalg.norm(ups) > 0.99
    assert "lighting as photographed: lighting/as_photographed.hdr" in report and (out / "lighting" / "as_photographed.hdr").is_file()


def test_nothing_posable_exits_non_zero(tmp_path, capsys, shared_data):
    folder = tmp_path / "junk"
    folder.mkdir()
    (folder / "a.jpg").write_text("not a photo")
    cv2.imwrite(str(folder / "b.png"), np.zeros((1, 1, 3), np.uint8))
    # No usable photo at all is bad input (exit 3), named file by file, and leaves no capture behind.
    assert main(["capture", str(folder), "-o", str(tmp_path / "capture")]) == 3
    err = capsys.readouterr().err
    assert "a.jpg: not an image" in err and "b.png: too small" in err and not (tmp_path / "capture").exists()
    # Real photos that cannot be posed together (one fox, one cake): the run finishes with exit 1.
    unrelated = tmp_path / "unrelated"
    unrelated.mkdir()
    shutil.copy(_fox(shared_data, 1)[0], unrelated / "fox.jpg")
    shutil.copy(sorted((shared_data / "real_vggsfm_cake" / "images").glob("*.jpg"))[0], unrelated / "cake.jpg")
    assert main(["capture", str(unrelated), "-o", str(tmp_path / "capture2"), "--max-side", "400"]) == 1
    assert "nothing could be posed" in capsys.readouterr().out


def test_imported_poses_and_alpha_masks(tmp_path, shared_data):
    lego = shared_data / "synth_nerf_lego_train"
    folder = tmp_path / "lego"
    folder.mkdir()
    for i in range(0, 24, 2):
        shutil.copy(lego / "train" / f"r_{i}.png", folder / f"r_{i}.png")
    code = main(["capture", str(folder), "-o", str(tmp_path / "capture"), "--masks", "alpha",
                 "--poses", str(lego / "transforms_train.json"), "--reference-originals"])
    assert code == 0
    summary_capture = Capture.open(tmp_path / "capture")
    assert not (tmp_path / "capture" / "originals").exists()  # referenced, not copied
    assert all(s.record.original.parent == folder for s in summary_capture.frames.values())
    summary = resume_capture(tmp_path / "capture")  # nothing left to do: the same capture back
    assert summary.registered == 12 and summary.masked == 12 and summary.prepared == 12
    capture = summary.capture
    view = capture.read_prepared(sorted(capture.cameras)[0])
    assert view.image_masked.shape == (256, 256, 3) and view.plucker.shape == (256, 256, 6)
    # The crop's mask is the alpha, and its rays are unit directions.
    assert 0.1 < view.mask.mean() < 0.9
    np.testing.assert_allclose(np.linalg.norm(view.plucker[..., :3], axis=-1), 1.0, atol=1e-5)
    # Normalisation put the lego's centre near the origin and its cameras outside radius 1.
    assert all(np.linalg.norm(c.center) > 1.0 for c in capture.cameras.values())
    # With no sparse points the masks sized the world (the cameras' guess alone made the lego 1.8 times
    # too large, and the ball cut its base plate round): every mask lies inside the ball's outline,
    # and the object fills the ball (the hull of the masks reaches past 0.7 R).
    for f, camera in capture.cameras.items():
        mask = capture.read_mask(f) > 127
        assert not (mask & (sphere_silhouette(camera, 1.0) < 128)).any(), f
    masks = {f: capture.read_mask(f) for f in capture.cameras}
    hull = carve_visual_hull(masks, capture.cameras, radius=1.0, resolution=48, min_views_fraction=1.0)
    assert np.linalg.norm(hull.occupied_centers(), axis=1).max() > 0.7
    # Cut-out renders show no background: no lighting estimate, said in the report, not an error.
    assert "lighting as photographed: none (no photo shows any background" in format_capture_report(summary)
    with pytest.raises(EnvironmentLoadError, match="no lighting estimate \\(no photo shows any background"):
        resolve_environment(tmp_path / "capture")


def test_imported_poses_with_automatic_masks_get_points_from_colmap(tmp_path, shared_data, capsys):
    """A transforms.json holds no sparse points, and the automatic masks are seeded by them: without
    COLMAP's, these twelve fox photos got twelve empty masks. Its points are carried into the imported
    frame; the imported cameras stay as the file has them."""
    folder = tmp_path / "fox"
    folder.mkdir()
    photos = sorted((shared_data / "real_instantngp_fox" / "images").glob("*.jpg"))[::5][:12]
    for p in photos:
        shutil.copy(p, folder / p.name)
    poses = shared_data / "real_instantngp_fox" / "transforms.json"
    assert main(["capture", str(folder), "-o", str(tmp_path / "capture"), "--poses", str(poses), "--max-side", "640"]) == 0
    assert "points for the automatic masks: " in capsys.readouterr().out  # the report says where they came from
    capture = Capture.open(tmp_path / "capture")
    assert capture.settings["pose_source"] == "transforms.json"
    note = [e for e in capture.history if e.get("action") == "points for imported poses"][0]["note"]
    assert "sparse points from COLMAP, aligned to the imported cameras over 12 frames" in note
    assert len(capture.points) > 300
    # The points are in the imported cameras' frame: what a photo observed projects into it.
    inside = []
    for f, camera in capture.cameras.items():
        xy, depth = camera.project(capture.points[capture.observations[f]])
        inside.append(np.mean((depth > 0) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)))
    assert min(inside) > 0.95
    # Measured: 7 of 12 masks (none without the points; 10 with COLMAP's own poses).
    assert sum(s.mask_status == "ok" for s in capture.frames.values()) >= 6


def test_an_interrupted_capture_resumes(tmp_path, shared_data):
    lego = shared_data / "synth_nerf_lego_train"
    folder = tmp_path / "lego"
    folder.mkdir()
    for i in range(6):
        shutil.copy(lego / "train" / f"r_{i}.png", folder / f"r_{i}.png")
    config = CaptureConfig(masks="alpha", poses=str(lego / "transforms_train.json"))
    calls = {"n": 0}

    def cancel_after_masks() -> bool:
        calls["n"] += 1
        return Capture.open(tmp_path / "capture").settings.get("completed", [])[-1:] == ["masks"]

    from lirm.engine.capture.ingest import Cancelled

    with pytest.raises(Cancelled):
        run_capture(folder, tmp_path / "capture", config, cancel=cancel_after_masks)
    reopened = Capture.open(tmp_path / "capture")
    assert "masks" in reopened.settings["completed"] and "crops" not in reopened.settings["completed"]
    assert main(["capture", "--resume", str(tmp_path / "capture"), "--masks", "alpha",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    assert len(list((tmp_path / "capture" / "prepared").glob("*.npz"))) == 6
    # the lighting before the crops: it decides the camera curve the crops are exposure-matched through
    assert Capture.open(tmp_path / "capture").settings["completed"][-2:] == ["lighting", "crops"]


@pytest.mark.slow
def test_adding_photos_keeps_old_frames(tmp_path, capsys, shared_data):
    first, more = tmp_path / "first", tmp_path / "more"
    first.mkdir()
    more.mkdir()
    for p in _fox(shared_data, 10):
        shutil.copy(p, first / p.name)
    for p in _fox(shared_data, 3, start=10):
        shutil.copy(p, more / p.name)
    out = tmp_path / "capture"
    assert main(["capture", str(first), "-o", str(out), "--max-side", "640", "--masks", "automatic", "--size", "64"]) == 0
    old = Capture.open(out)
    old_names = {f: s.record.original.name for f, s in old.frames.items()}
    assert main(["capture", "--add", str(more), str(out), "--max-side", "640", "--masks", "automatic", "--size", "64"]) == 0
    new = Capture.open(out)
    assert {f: new.frames[f].record.original.name for f in old_names} == old_names  # same ids, same photos
    assert len(new.frames) == 13
    assert len(new.cameras) >= 12
    capsys.readouterr()


def test_a_mask_fix_propagates_to_the_other_views(tmp_path, shared_data, capsys):
    """Lego with alpha masks, then every mask gets a false blob beside the object; the user fixes one
    view and the blob disappears from the others too (they share the hull's verdict)."""
    lego = shared_data / "synth_nerf_lego_train"
    folder = tmp_path / "lego"
    folder.mkdir()
    for i in range(0, 40, 4):
        shutil.copy(lego / "train" / f"r_{i}.png", folder / f"r_{i}.png")
    config = CaptureConfig(masks="alpha", poses=str(lego / "transforms_train.json"))
    capture = run_capture(folder, tmp_path / "capture", config).capture
    from lirm.engine.capture.visual_hull import sphere_silhouette

    clean = {f: capture.read_mask(f) for f in capture.cameras}
    # A false blob: a small ball floating beside the object (the lego reaches x = +-0.4 in the world
    # its masks sized), added to every view's mask.
    blob_center = np.array([0.8, 0.0, 0.0])
    blobbed = {}
    for f, cam in capture.cameras.items():
        blob = sphere_silhouette(cam, 0.08, center=blob_center) > 0
        blobbed[f] = np.where(blob | (clean[f] > 127), 255, 0).astype(np.uint8)
        capture.write_mask(f, blobbed[f], "alpha", "ok")
    capture.save()
    # The user fixes the view where the error shows most: the blob against the background.
    fixed_frame = max(capture.cameras, key=lambda f: int(((blobbed[f] > 127) & (clean[f] < 128)).sum()))
    fixed_path = tmp_path / "fixed.png"
    cv2.imwrite(str(fixed_path), clean[fixed_frame])
    assert main(["capture", "--fix-mask", fixed_frame, str(fixed_path), str(capture.root)]) == 0
    assert "other views" in capsys.readouterr().out
    after = Capture.open(capture.root)
    improved, total_before, total_after = 0, 0, 0
    for f in after.cameras:
        if f == fixed_frame:
            continue
        before_extra = int(((blobbed[f] > 127) & (clean[f] < 128)).sum())
        after_extra = int(((after.read_mask(f) > 127) & (clean[f] < 128)).sum())
        assert after_extra <= before_extra  # a fix only ever removes
        improved += after_extra < 0.5 * before_extra
        total_before += before_extra
        total_after += after_extra
    # Views that see the blob's place against the background lose it (measured: 4 of 9 views, the
    # false pixels in the other views down by 83%); views that see it over the object cannot.
    assert improved >= 2
    assert total_after < 0.7 * total_before
    assert after.frames[fixed_frame].mask_source == "fixed"


@pytest.mark.slow
def test_pipeline_on_a_gltf_photographed_on_a_floor_under_an_hdri(tmp_path, shared_data, gl_context):
    """The issue's rendered capture: a glTF model on a textured ground plane under a real HDRI, with
    known cameras. Poses and automatic masks are checked against the truth."""
    from lirm.engine.assets.environment_files import load_environment_file
    from lirm.engine.demo import capture_accuracy
    from lirm.engine.synth.capture_scene import SyntheticCaptureConfig, render_synthetic_capture
    from lirm.renderer.pbr_renderer import PBRRenderer

    renderer = PBRRenderer(gl_context)
    try:
        env = load_environment_file(shared_data / "envmaps" / "forest_slope_1k.hdr")
        model = str(shared_data / "pbr_models" / "WaterBottle_tex256.glb")
        # Lit by the bare HDRI, as when this check was set: lit by the floor too (the demo's shoot),
        # the bottle reflects the gravel and the automatic masks miss its dark cap (IoU mean 0.83;
        # README, "Captures", masks).
        shoot = render_synthetic_capture(renderer, env, SyntheticCaptureConfig(object_name=model, floor_lights_object=False))
    finally:
        renderer.release()
    photos = tmp_path / "photos"
    photos.mkdir()
    for k, image in shoot.images.items():
        cv2.imwrite(str(photos / f"shot_{k}.jpg"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    summary = run_capture(photos, tmp_path / "capture")
    accuracy = capture_accuracy(summary.capture, shoot.cameras, {f"shot_{k}": m for k, m in shoot.masks.items()})
    assert summary.registered == 16
    assert accuracy["rotation_deg_max"] < 1.0 and accuracy["center_error_max"] < 0.01
    assert accuracy["mask_iou_mean"] >= 0.9, accuracy
    # The whole bottle is in the model's ball, its cap too (which carries no sparse points): the true
    # masks' hull, carved with the capture's cameras, stays under R above the origin (it rose to
    # 1.25 R before the world was fitted to the masks; the hull is a little above the true top).
    capture = summary.capture
    names = {state.record.original.stem: fid for fid, state in capture.frames.items()}
    true_masks = {names[f"shot_{k}"]: m for k, m in shoot.masks.items()}
    hull = carve_visual_hull(true_masks, {f: capture.cameras[f] for f in true_masks}, radius=1.4, resolution=96,
                             min_views_fraction=1.0, within_sphere=True)
    normal, _ = capture.normalization.plane
    assert float((hull.occupied_centers() @ normal).max()) < 1.0
    # The lighting the photos were taken in, from their backgrounds, usable wherever an HDRI is.
    lighting = resolve_environment(tmp_path / "capture")
    assert lighting.name == "as photographed" and lighting.radiance.shape == (64, 128, 3)
    assert (tmp_path / "capture" / "lighting" / "as_photographed.png").is_file()
    report = format_capture_report(summary)
    assert "lighting as photographed: lighting/as_photographed.hdr from the backgrounds of 16 photos" in report
    # Photos at one exposure, without EXIF: their backgrounds say so, and nothing is brightened
    # (exposure_estimate.py; the photos exposed apart are in test_exposure_estimate.py).
    assert "exposure from the photos' shared backgrounds" in report and "one exposure, nothing matched" in report, report
    assert not [e for e in capture.history if e.get("action") == "crops"][-1].get("exposure_matched")
