"""Issue 20: what a careless user did to `lirm capture`, each case reproduced on small data. Nothing
a user made is lost, and every failure is a sentence that names the file and the fix."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.masks import cut_by_border
from lirm.engine.capture.report import format_capture_report
from lirm.engine.cli import main


def _lego_photos(shared_data: Path, folder: Path, count: int = 8) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(0, 5 * count, 5):
        shutil.copy(shared_data / "synth_nerf_lego_train" / "train" / f"r_{i}.png", folder / f"r_{i}.png")
    return folder


def _copy(capture: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "capture"
    shutil.copytree(capture, copy)
    return copy


def _digest(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


# ---- case 2: a mask correction cannot ruin the capture --------------------------------------------------
def test_an_empty_mask_correction_is_refused_and_nothing_changes(lego_capture, tmp_path, capsys):
    capture = _copy(lego_capture, tmp_path)
    before = _digest(capture / "masks") | _digest(capture / "prepared")
    frame = sorted(Capture.open(capture).cameras)[0]
    cam = Capture.open(capture).cameras[frame]
    for name, image in (("empty.png", np.zeros((cam.height, cam.width), np.uint8)),
                        ("speck.png", np.pad(np.full((2, 2), 255, np.uint8), ((0, cam.height - 2), (0, cam.width - 2))))):
        cv2.imwrite(str(tmp_path / name), image)
        assert main(["capture", "--fix-mask", frame, str(tmp_path / name), str(capture)]) == 3
        err = capsys.readouterr().err
        assert frame in err and "empty" in err and "paint the object white" in err and "nothing was changed" in err
    assert _digest(capture / "masks") | _digest(capture / "prepared") == before


def test_a_correction_that_would_gut_other_views_is_withheld_and_can_be_undone(lego_capture, tmp_path, capsys):
    capture = _copy(lego_capture, tmp_path)
    opened = Capture.open(capture)
    frame = sorted(opened.cameras)[0]
    before = _digest(capture / "masks") | _digest(capture / "prepared")
    mask = opened.read_mask(frame)
    ys, xs = np.nonzero(mask > 127)
    cut = np.zeros_like(mask)  # only a quarter of the object kept: the other views would lose most of theirs
    cut[ys.min():(ys.min() + ys.max()) // 2, xs.min():(xs.min() + xs.max()) // 2] = 255
    cut &= mask
    cv2.imwrite(str(tmp_path / "quarter.png"), cut)
    assert main(["capture", "--fix-mask", frame, str(tmp_path / "quarter.png"), str(capture)]) == 0
    out = capsys.readouterr().out
    after = Capture.open(capture)
    withheld = [line for line in out.splitlines() if "not applied to" in line]
    assert withheld and "of its mask" in withheld[0]
    for line in withheld:  # a withheld view keeps its mask and its crop
        other = line.split("not applied to ")[1].split(":")[0]
        assert _digest(capture / "masks")[f"{other}.png"] == before[f"{other}.png"]
    for f in after.cameras:  # prepared/ agrees with masks/: a crop only where the mask is usable
        assert after.prepared_path(f).exists() == (after.frames[f].mask_status == "ok")
    assert "--undo-fix-mask" in out
    assert main(["capture", "--undo-fix-mask", str(capture)]) == 0
    assert frame in capsys.readouterr().out
    assert {k: v for k, v in (_digest(capture / "masks") | _digest(capture / "prepared")).items() if "/" not in k} == before
    assert Capture.open(capture).frames[frame].mask_status == opened.frames[frame].mask_status
    assert main(["capture", "--undo-fix-mask", str(capture)]) == 3  # nothing left to undo
    assert "no mask correction to undo" in capsys.readouterr().err


# ---- case 4: a failed start leaves nothing that blocks the retry ----------------------------------------
@pytest.mark.parametrize("source", ["missing", "empty", "bad_video", "camera:99"])
def test_a_failed_start_creates_nothing(tmp_path, capsys, source):
    out = tmp_path / "X"
    if source == "missing":
        inputs = str(tmp_path / "no" / "such" / "folder")
    elif source == "empty":
        (tmp_path / "empty").mkdir()
        inputs = str(tmp_path / "empty")
    elif source == "bad_video":
        (tmp_path / "clip.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 this is not a video")
        inputs = str(tmp_path / "clip.mp4")
    else:
        inputs = source
    assert main(["capture", inputs, "-o", str(out)]) == 3
    err = capsys.readouterr().err
    assert not out.exists(), f"{source}: left {list(out.rglob('*'))}"
    if source == "empty":
        assert "no photos found" in err and "overlap" not in err


def test_photos_in_subfolders_are_named_and_nothing_is_created(tmp_path, shared_data, capsys):
    """A phone's export (DCIM/100APPLE, or one folder a day): the photos are a level or two down. The
    capture does not take in every subfolder (they may hold other objects); it names those that
    hold photos, with how many, and the folder to point at."""
    root = tmp_path / "phone"
    _lego_photos(shared_data, root / "DCIM" / "100APPLE", 3)
    _lego_photos(shared_data, root / "2026-12-06", 2)
    (root / ".thumbnails").mkdir()
    shutil.copy(shared_data / "synth_nerf_lego_train" / "train" / "r_0.png", root / ".thumbnails" / "r_0.png")
    (root / "notes.txt").write_text("the red one")
    before = _digest(root)
    out = tmp_path / "X"
    assert main(["capture", str(root), "-o", str(out)]) == 3
    err = capsys.readouterr().err
    assert "no photos directly in it; its subfolders hold photos: 2026-12-06 (2), DCIM/100APPLE (3)." in err, err
    assert f"for example {root / '2026-12-06'}" in err and ".thumbnails" not in err
    assert not out.exists() and _digest(root) == before


def test_a_retry_after_a_failed_start_works(tmp_path, shared_data, capsys):
    out = tmp_path / "X"
    assert main(["capture", str(tmp_path / "nope"), "-o", str(out)]) == 3
    photos = _lego_photos(shared_data, tmp_path / "photos", 4)
    lego = shared_data / "synth_nerf_lego_train"
    assert main(["capture", str(photos), "-o", str(out), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0


# ---- case 10: the smaller ones ----------------------------------------------------------------------------
def test_a_zero_byte_photo_is_called_an_empty_file(tmp_path, shared_data, capsys):
    photos = _lego_photos(shared_data, tmp_path / "photos", 4)
    (photos / "r_99.png").write_bytes(b"")
    lego = shared_data / "synth_nerf_lego_train"
    assert main(["capture", str(photos), "-o", str(tmp_path / "c"), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    assert "skipped r_99.png: empty file (0 bytes)" in capsys.readouterr().out


def test_a_folder_of_only_unusable_files_is_an_error_naming_them(tmp_path, capsys):
    folder = tmp_path / "photos"
    folder.mkdir()
    (folder / "a.jpg").write_bytes(b"")
    (folder / "b.jpg").write_text("not a photo")
    assert main(["capture", str(folder), "-o", str(tmp_path / "c")]) == 3
    err = capsys.readouterr().err
    assert "none of its 2 files is a usable photo" in err and "a.jpg: empty file" in err
    assert not (tmp_path / "c").exists()


def test_an_output_folder_inside_the_photo_folder_is_refused(tmp_path, shared_data, capsys):
    photos = _lego_photos(shared_data, tmp_path / "photos", 2)
    assert main(["capture", str(photos), "-o", str(photos / "capture")]) == 3
    assert "inside the photo folder" in capsys.readouterr().err and not (photos / "capture").exists()


def test_an_interrupted_capture_is_resumed_not_added_to(lego_capture, tmp_path, shared_data, capsys):
    capture = _copy(lego_capture, tmp_path)
    data = json.loads((capture / "capture.json").read_text())
    data["settings"]["completed"] = ["pose", "normalize"]  # as a killed run leaves it
    (capture / "capture.json").write_text(json.dumps(data))
    assert main(["capture", str(shared_data / "synth_nerf_lego_train" / "train"), "-o", str(capture)]) == 3
    err = capsys.readouterr().err
    assert f"lirm capture --resume {capture}" in err and "--add" not in err


def test_mask_files_in_the_photo_folder_are_not_counted_as_skipped_photos(tmp_path, shared_data, capsys):
    photos = _lego_photos(shared_data, tmp_path / "photos", 4)
    masks = photos / "masks"
    masks.mkdir()
    for p in sorted(photos.glob("*.png")):
        alpha = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)[:, :, 3]
        cv2.imwrite(str(masks / p.name), np.where(alpha > 127, 255, 0).astype(np.uint8))
    lego = shared_data / "synth_nerf_lego_train"
    assert main(["capture", str(photos), "-o", str(tmp_path / "c"), "--masks", str(masks), "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    out = capsys.readouterr().out
    assert "photos accepted: 4, skipped: 0" in out and "masks ok: 4 of 4" in out


def test_a_mask_message_does_not_double_its_word(lego_capture, tmp_path):
    capture = Capture.open(_copy(lego_capture, tmp_path))
    frame = sorted(capture.cameras)[0]
    capture.frames[frame].mask_status = "empty: no object found in this view"
    from lirm.engine.capture.pipeline import _summary

    report = format_capture_report(_summary(capture))
    assert "mask empty: no object found" in report and "mask mask" not in report


def test_an_object_cut_by_the_image_border_is_flagged():
    mask = np.zeros((100, 120), np.uint8)
    mask[30:70, 40:80] = 255
    assert cut_by_border(mask) is None
    mask[30:70, 0:40] = 255  # runs out of the left edge
    message = cut_by_border(mask)
    assert message and "left" in message and "runs out of the picture" in message
    mask2 = np.zeros((100, 120), np.uint8)
    mask2[99, 60:62] = 255  # two pixels of contact: a loose outline, not a cut
    assert cut_by_border(mask2) is None


# ---- case 8: a damaged capture is noticed, repaired where it can be, named where it cannot --------------
def test_a_deleted_crop_and_mask_are_made_again(lego_capture, tmp_path, capsys):
    capture = _copy(lego_capture, tmp_path)
    frames = sorted(Capture.open(capture).cameras)
    mask_before = cv2.imread(str(capture / "masks" / f"{frames[1]}.png"), cv2.IMREAD_GRAYSCALE)
    (capture / "prepared" / f"{frames[0]}.npz").unlink()
    (capture / "masks" / f"{frames[1]}.png").unlink()
    assert main(["capture", "--check", str(capture)]) == 0
    out = capsys.readouterr().out
    assert f"{frames[0]}: prepared crop cut again" in out and f"{frames[1]}: mask made again (alpha)" in out
    assert np.array_equal(cv2.imread(str(capture / "masks" / f"{frames[1]}.png"), cv2.IMREAD_GRAYSCALE), mask_before)
    assert all((capture / "prepared" / f"{f}.npz").is_file() for f in frames)
    assert main(["capture", "--check", str(capture)]) == 0
    assert "every file capture.json lists is there" in capsys.readouterr().out


def test_reconstruct_repairs_a_deleted_crop_instead_of_dropping_the_view(lego_capture, tmp_path, capsys):
    from lirm.engine.reconstruction.session import open_checked, prepared_views

    capture = _copy(lego_capture, tmp_path)
    frames = sorted(Capture.open(capture).cameras)
    (capture / "prepared" / f"{frames[2]}.npz").write_bytes(b"PK\x03\x04 truncated")
    assert list(prepared_views(open_checked(capture))) == frames


def test_what_cannot_be_made_again_is_named(lego_capture, tmp_path, capsys):
    capture = _copy(lego_capture, tmp_path)
    opened = Capture.open(capture)
    frame = sorted(opened.cameras)[3]
    image = opened.image_path(frame)
    image.unlink()
    assert main(["capture", "--check", str(capture)]) == 1
    out = capsys.readouterr().out
    assert f"cannot be repaired: {frame}" in out and "lirm capture --add" in out


# ---- case 7: a full disk stops the capture with a sentence and a folder that resumes ---------------------
def test_a_full_disk_stops_before_the_stage_and_resume_goes_on(tmp_path, shared_data, capsys, monkeypatch):
    """The disk is full from the pose stage on (the space query answers as a full disk would; filling a
    real disk is not possible in a test): the capture stops before COLMAP with exit 4, says how much
    space it needs, and `--resume` finishes it once there is room."""
    from collections import namedtuple

    from lirm.engine.capture import disk_space, pipeline

    photos = _lego_photos(shared_data, tmp_path / "photos", 4)
    lego = shared_data / "synth_nerf_lego_train"
    out = tmp_path / "c"
    real_usage = disk_space.shutil.disk_usage
    Usage = namedtuple("Usage", "total used free")
    real_ingest = pipeline.ingest_photos

    def ingest_then_fill(*args, **kwargs):
        result = real_ingest(*args, **kwargs)
        monkeypatch.setattr(disk_space.shutil, "disk_usage", lambda p: Usage(10 * 2**30, 10 * 2**30 - 2**20, 2**20))
        return result

    monkeypatch.setattr(pipeline, "ingest_photos", ingest_then_fill)
    assert main(["capture", str(photos), "-o", str(out), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 4
    err = capsys.readouterr().err
    assert "not enough free disk space to pose the photos" in err and "1 MB are free" in err
    assert f"lirm capture --resume {out}" in err
    assert not list(out.rglob("*-wal")) and not list(out.rglob("*-shm"))
    monkeypatch.setattr(disk_space.shutil, "disk_usage", real_usage)
    monkeypatch.setattr(pipeline, "ingest_photos", real_ingest)
    assert main(["capture", "--resume", str(out), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    assert "network views prepared: 4" in capsys.readouterr().out


def test_a_capture_with_nothing_to_reconstruct_is_not_a_success(tmp_path, shared_data, capsys):
    photos = _lego_photos(shared_data, tmp_path / "photos", 3)
    masks = tmp_path / "masks"
    masks.mkdir()
    for p in photos.glob("*.png"):
        cv2.imwrite(str(masks / p.name), np.zeros((800, 800), np.uint8))
    lego = shared_data / "synth_nerf_lego_train"
    assert main(["capture", str(photos), "-o", str(tmp_path / "c"), "--masks", str(masks), "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 1
    out = capsys.readouterr().out
    assert "network views prepared: 0" in out and "no view could be prepared" in out and "--fix-mask" in out



def test_a_view_whose_mask_runs_out_of_the_picture_is_used_and_named(tmp_path, shared_data, capsys):
    """Lego renders whose object reaches the left edge (a band of it painted in, as if the photo had
    been framed too tight): the views stay usable (their rays are valid) and the report names each."""
    photos = tmp_path / "photos"
    photos.mkdir()
    lego = shared_data / "synth_nerf_lego_train"
    for i in range(0, 20, 5):
        image = cv2.imread(str(lego / "train" / f"r_{i}.png"), cv2.IMREAD_UNCHANGED)
        image[360:440, :420] = (90, 90, 90, 255)  # a bar from the left border into the object
        cv2.imwrite(str(photos / f"r_{i}.png"), image)
    assert main(["capture", str(photos), "-o", str(tmp_path / "c"), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    out = capsys.readouterr().out
    assert "network views prepared: 4" in out and "masks used with a warning: 4" in out
    assert out.count("runs out of the picture (left border)") == 4


# ---- case 3: the same photos give the same capture, every time ---------------------------------------------
@pytest.mark.slow
def test_the_same_photos_give_the_same_poses_and_masks_in_every_run(tmp_path, shared_data):
    """Three separate `lirm capture` processes on the same 8 fox photos (automatic masks) write
    byte-identical cameras, masks and crops. With feature extraction on two threads COLMAP numbered
    the images in the order they finished, and the same photos gave focal lengths 273.7-275.3 px,
    and through the poses different automatic masks."""
    import subprocess
    import sys

    photos = tmp_path / "photos"
    photos.mkdir()
    for p in sorted((shared_data / "real_instantngp_fox" / "images").glob("*.jpg"))[:8]:
        shutil.copy(p, photos / p.name)
    runs = []
    for k in range(3):
        out = tmp_path / f"capture_{k}"
        done = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "capture", str(photos), "-o", str(out),
                               "--max-side", "400", "--size", "32"], capture_output=True, text=True)
        assert done.returncode == 0, done.stdout + done.stderr
        masks_line = next(line for line in done.stdout.splitlines() if "masks ok" in line)
        runs.append(((out / "transforms.json").read_bytes(), _digest(out / "masks"), _digest(out / "prepared"),
                     masks_line))
    assert runs[0][3].strip().startswith("masks ok: 8 of 8"), runs[0][3]
    for other in runs[1:]:
        assert other[0] == runs[0][0]  # the same cameras, to the last bit
        assert other[1] == runs[0][1] and other[2] == runs[0][2] and other[3] == runs[0][3]
