"""Photo ingest on real photos: what a user dropping a messy folder sees in the per-file report."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image, ImageFile

from lirm.engine.capture.ingest import SIDE_FILE_REASON, Cancelled, IngestConfig, ingest_photos
from lirm.engine.errors import LirmUserError


def _fox(shared_data: Path, n: int) -> Path:
    path = shared_data / "real_instantngp_fox" / "images" / f"{n:04d}.jpg"
    if not path.exists():
        pytest.skip(f"{path} missing")
    return path


def _snapshot(folder: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def _read_rgb(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA if image.shape[2] == 4 else cv2.COLOR_BGR2RGB)


@pytest.fixture(scope="module")
def messy_folder(shared_data, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("photos")
    for i in range(1, 6):
        (folder / f"fox_{i:02d}.jpg").write_bytes(_fox(shared_data, i).read_bytes())
    whole = _fox(shared_data, 6).read_bytes()
    (folder / "corrupt.jpg").write_bytes(whole[: int(len(whole) * 0.4)])
    (folder / "bad.jpg").write_text("this is not a photo\n")
    cv2.imwrite(str(folder / "tiny.png"), np.zeros((1, 1, 3), np.uint8))
    (folder / "fox_02_copy.jpg").write_bytes((folder / "fox_02.jpg").read_bytes())
    lego = shared_data / "synth_nerf_lego_train" / "train" / "r_0.png"
    (folder / "lego_rgba.png").write_bytes(lego.read_bytes())
    # Stored portrait pixels, tagged "rotate 90 degrees clockwise to display" (orientation 6).
    exif = Image.new("RGB", (1, 1)).getexif()
    exif[0x0112] = 6
    Image.open(_fox(shared_data, 7)).save(folder / "rotated.jpg", exif=exif.tobytes(), quality=92)
    grey16 = (np.linspace(0, 65535, 120)[None, :] * np.ones((90, 1))).astype(np.uint16)
    cv2.imwrite(str(folder / "grey16.png"), grey16)
    (folder / "sketch.psd").write_bytes(b"8BPS" + bytes(60))
    (folder / "notes.txt").write_text("shot on a cloudy day\n")
    (folder / "transforms.json").write_text("{}\n")
    for p in folder.iterdir():
        p.chmod(0o444)  # the user's files are read-only: any attempt to modify them fails loudly
    return folder


@pytest.fixture(scope="module")
def first_ingest(messy_folder, tmp_path_factory):
    before = _snapshot(messy_folder)
    root = tmp_path_factory.mktemp("capture")
    calls = []
    records, reports = ingest_photos(messy_folder, root, progress=lambda done, total: calls.append((done, total)))
    return root, records, reports, before, calls


def test_every_file_is_reported_with_a_reason(first_ingest, messy_folder):
    root, records, reports, _, calls = first_ingest
    by_name = {r.path.name: r for r in reports}
    assert sorted(by_name) == sorted(p.name for p in messy_folder.iterdir())
    accepted = sorted(name for name, r in by_name.items() if r.accepted)
    assert accepted == ["fox_01.jpg", "fox_02.jpg", "fox_03.jpg", "fox_04.jpg", "fox_05.jpg",
                        "grey16.png", "lego_rgba.png", "rotated.jpg"]
    assert "incomplete" in by_name["corrupt.jpg"].reason
    assert "not an image" in by_name["bad.jpg"].reason
    assert "too small (1x1" in by_name["tiny.png"].reason
    assert by_name["fox_02_copy.jpg"].reason == "duplicate of fox_02.jpg (frame 0002)"
    assert "PSD is not read here" in by_name["sketch.psd"].reason
    assert by_name["notes.txt"].reason == by_name["transforms.json"].reason == SIDE_FILE_REASON
    assert [r.frame_id for r in records] == [f"{i:04d}" for i in range(1, 9)]
    assert {by_name[name].frame_id for name in accepted} == {r.frame_id for r in records}
    assert calls[0] == (0, len(calls) - 1) and calls[-1] == (len(calls) - 1, len(calls) - 1)


def test_input_folder_is_untouched(first_ingest, messy_folder):
    assert _snapshot(messy_folder) == first_ingest[3]


def test_working_copies_are_capped_upright_and_keep_alpha(first_ingest, messy_folder, shared_data):
    root, records, reports, _, _ = first_ingest
    rec = {r.original.name: r for r in records}
    fox = rec["fox_01.jpg"]
    assert fox.image == Path("images/0001.jpg") and not fox.has_alpha
    assert (fox.width, fox.height) == (720, 1280)  # 1080x1920 portrait, long side capped at 1280
    assert _read_rgb(root / fox.image).shape == (1280, 720, 3)

    # EXIF orientation 6: the working copy is the stored image turned 90 degrees clockwise, and has
    # no orientation tag left for a viewer to apply a second time.
    turned = rec["rotated.jpg"]
    assert (turned.width, turned.height) == (1280, 720)
    copy = _read_rgb(root / turned.image)
    stored = cv2.cvtColor(cv2.imread(str(_fox(shared_data, 7))), cv2.COLOR_BGR2RGB)
    expected = cv2.resize(cv2.rotate(stored, cv2.ROTATE_90_CLOCKWISE), (1280, 720), interpolation=cv2.INTER_AREA)
    assert np.abs(copy.astype(int) - expected).mean() < 3.0
    assert Image.open(root / turned.image).getexif().get(0x0112, 1) == 1
    # cv2's own EXIF handling (IMREAD_COLOR applies it) agrees.
    by_cv2 = cv2.cvtColor(cv2.imread(str(messy_folder / "rotated.jpg"), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert np.abs(cv2.resize(by_cv2, (1280, 720), interpolation=cv2.INTER_AREA).astype(int) - copy).mean() < 3.0

    lego = rec["lego_rgba.png"]
    assert lego.has_alpha and lego.image.suffix == ".png" and (lego.width, lego.height) == (800, 800)
    source = np.asarray(Image.open(messy_folder / "lego_rgba.png"))
    assert np.array_equal(_read_rgb(root / lego.image), source)  # 800 px: stored as is, alpha and all

    grey = _read_rgb(root / rec["grey16.png"].image)
    assert grey.dtype == np.uint8 and grey.shape == (90, 120, 3)
    assert grey[0, 0].tolist() == [0, 0, 0] and grey[0, -1].tolist() == [255, 255, 255]


def test_originals_are_copied_byte_for_byte(first_ingest, messy_folder):
    root, records, _, _, _ = first_ingest
    for record in records:
        assert record.original == Path("originals") / record.original.name
        data = (root / record.original).read_bytes()
        assert data == (messy_folder / record.original.name).read_bytes()
        assert record.sha256 == hashlib.sha256(data).hexdigest()
    assert not [p for p in root.rglob("*") if p.name.endswith(".tmp") or ".tmp." in p.name]


def test_adding_a_second_folder_keeps_ids_and_catches_duplicates(first_ingest, messy_folder, shared_data, tmp_path):
    root, first_records, _, _, _ = first_ingest
    folder = tmp_path / "more"
    folder.mkdir()
    (folder / "fox_06.jpg").write_bytes(_fox(shared_data, 8).read_bytes())
    (folder / "again.jpg").write_bytes((messy_folder / "fox_03.jpg").read_bytes())
    small = cv2.resize(cv2.imread(str(messy_folder / "fox_04.jpg")), (540, 960), interpolation=cv2.INTER_AREA)
    cv2.imwrite(str(folder / "fox_04_small.jpg"), small, [cv2.IMWRITE_JPEG_QUALITY, 80])

    records, reports = ingest_photos(folder, root, IngestConfig(copy_originals=False), existing=first_records)
    by_name = {r.path.name: r for r in reports}
    assert by_name["again.jpg"].reason == "duplicate of fox_03.jpg (frame 0003)"
    assert by_name["fox_04_small.jpg"].reason == "nearly identical to fox_04.jpg (frame 0004)"
    assert [r.frame_id for r in records] == ["0009"] and by_name["fox_06.jpg"].frame_id == "0009"
    new = records[0]
    assert new.original == (folder / "fox_06.jpg").resolve()  # referenced, not copied
    assert not (root / "originals" / "fox_06.jpg").exists()
    assert (root / new.image).is_file()


def test_a_list_of_files_and_cancelling(messy_folder, tmp_path):
    files = [messy_folder / "fox_01.jpg", messy_folder / "bad.jpg", messy_folder / "fox_03.jpg", tmp_path / "gone.jpg"]
    records, reports = ingest_photos(files, tmp_path / "cap")
    assert [r.frame_id for r in records] == ["0001", "0002"]
    assert {r.path.name: r.reason for r in reports}["gone.jpg"] == "not found"

    asked = []

    def cancel() -> bool:
        asked.append(1)
        return len(asked) > 2

    with pytest.raises(Cancelled) as info:
        ingest_photos(files, tmp_path / "cap2", cancel=cancel)
    assert [r.frame_id for r in info.value.records] == ["0001"]  # what was done is complete and known
    assert (tmp_path / "cap2" / info.value.records[0].image).stat().st_size > 0
    with pytest.raises(LirmUserError, match="nowhere"):
        ingest_photos(tmp_path / "nowhere", tmp_path / "cap3")


def test_truncation_is_caught_even_if_pillow_is_told_to_tolerate_it(messy_folder, tmp_path, monkeypatch):
    monkeypatch.setattr(ImageFile, "LOAD_TRUNCATED_IMAGES", True)
    records, reports = ingest_photos([messy_folder / "corrupt.jpg"], tmp_path / "cap")
    assert not records and "incomplete" in reports[0].reason


@pytest.mark.parametrize("orientation", range(1, 9))
def test_every_exif_orientation_matches_opencv(orientation, shared_data, tmp_path):
    # An asymmetric picture, tagged; cv2.imread(IMREAD_COLOR) applies the tag independently of us.
    stored = Image.open(_fox(shared_data, 9)).resize((90, 160)).crop((0, 0, 90, 120))
    exif = Image.new("RGB", (1, 1)).getexif()
    exif[0x0112] = orientation
    path = tmp_path / "tagged.jpg"
    stored.save(path, exif=exif.tobytes(), quality=95)
    records, _ = ingest_photos([path], tmp_path / "cap", IngestConfig(min_side=16))
    copy = _read_rgb(tmp_path / "cap" / records[0].image)
    by_cv2 = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    assert copy.shape == by_cv2.shape == ((90, 120, 3) if orientation >= 5 else (120, 90, 3))
    assert np.abs(copy.astype(int) - by_cv2).mean() < 3.0
