"""The photo formats a user brings besides JPEG and PNG: an iPhone's HEIC, a raw developer's 16-bit
TIFF, WebP, and a camera's raw files with or without their JPEG twins."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from lirm.engine.capture.ingest import ingest_photos
from lirm.engine.capture.photo_formats import enable_heif


def _fox_rgb(shared_data: Path, n: int, side: int = 320) -> np.ndarray:
    path = shared_data / "real_instantngp_fox" / "images" / f"{n:04d}.jpg"
    if not path.exists():
        pytest.skip(f"{path} missing")
    image = Image.open(path).convert("RGB")
    image.thumbnail((side, side))
    return np.asarray(image)


def _working_copy(root: Path, record) -> np.ndarray:
    return cv2.cvtColor(cv2.imread(str(root / record.image), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def formats_folder(shared_data, tmp_path_factory) -> tuple[Path, dict[str, np.ndarray]]:
    """One photo per format, each a different fox view so that none is taken for another's duplicate;
    returns the folder and each file's upright pixels as the user sees them."""
    assert enable_heif(), "pillow-heif is a dependency (pyproject.toml)"
    folder = tmp_path_factory.mktemp("formats")
    upright = {}
    # An iPhone photo: stored landscape, tagged "turn 90 degrees clockwise to display".
    stored = _fox_rgb(shared_data, 1)
    exif = Image.new("RGB", (1, 1)).getexif()
    exif[0x0112] = 6
    Image.fromarray(stored).save(folder / "IMG_0001.HEIC", exif=exif.tobytes(), quality=95)
    upright["IMG_0001.HEIC"] = np.rot90(stored, k=-1)
    # A raw developer's export: 16 bits a channel.
    rgb = _fox_rgb(shared_data, 12)
    cv2.imwrite(str(folder / "developed.tif"), (rgb[:, :, ::-1].astype(np.uint16) * 257))
    upright["developed.tif"] = rgb
    rgb = _fox_rgb(shared_data, 21)
    Image.fromarray(rgb).save(folder / "web.webp", quality=95)
    upright["web.webp"] = rgb
    # A camera set to RAW + JPEG, and a raw file whose JPEG was not copied.
    rgb = _fox_rgb(shared_data, 30)
    Image.fromarray(rgb).save(folder / "DSC_0030.JPG", quality=95)
    upright["DSC_0030.JPG"] = rgb
    (folder / "DSC_0030.NEF").write_bytes(b"II*\x00" + bytes(200))
    (folder / "DSC_0031.NEF").write_bytes(b"II*\x00" + bytes(200))
    (folder / "IMG_0001.MOV").write_bytes(bytes(64))  # the Live Photo's clip beside the HEIC
    (folder / "walkaround.mp4").write_bytes(bytes(64))
    for p in folder.iterdir():
        p.chmod(0o444)
    return folder, upright


def test_heic_tiff_and_webp_become_upright_working_copies(formats_folder, tmp_path):
    folder, upright = formats_folder
    records, reports = ingest_photos(folder, tmp_path)
    by_name = {r.original.name: r for r in records}
    assert sorted(by_name) == sorted(upright)
    for name, expected in upright.items():
        copy = _working_copy(tmp_path, by_name[name])
        assert copy.shape == expected.shape, name  # the HEIC turned upright once, not twice or never
        assert np.abs(copy.astype(float) - expected).mean() < 4.0, name  # lossy codecs, same picture
        assert (tmp_path / by_name[name].original).read_bytes() == (folder / name).read_bytes()


def test_raw_files_and_videos_are_explained_not_read(formats_folder, tmp_path):
    folder, _ = formats_folder
    _, reports = ingest_photos(folder, tmp_path)
    by_name = {r.path.name: r for r in reports}
    assert not by_name["DSC_0030.NEF"].accepted and "the photo is used" in by_name["DSC_0030.NEF"].reason
    lone = by_name["DSC_0031.NEF"]
    assert not lone.accepted and "NEF" in lone.reason and "export the raw files as JPEG or 16-bit TIFF" in lone.reason
    assert "Live Photo's clip beside its photo" in by_name["IMG_0001.MOV"].reason
    assert "a video is captured on its own (`lirm capture " in by_name["walkaround.mp4"].reason


def test_a_heic_named_jpg_still_opens(formats_folder, tmp_path):
    """Some transfer tools keep the HEIC bytes under a .jpg name: the contents decide, not the name."""
    folder, upright = formats_folder
    misnamed = tmp_path / "photos" / "IMG_0001.jpg"
    misnamed.parent.mkdir()
    misnamed.write_bytes((folder / "IMG_0001.HEIC").read_bytes())
    records, reports = ingest_photos(misnamed.parent, tmp_path / "capture")
    assert [r.accepted for r in reports] == [True]
    assert _working_copy(tmp_path / "capture", records[0]).shape == upright["IMG_0001.HEIC"].shape
