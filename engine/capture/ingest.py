"""Ingest: the user's photos -> working copies in a capture, with a per-file report.

The user's files are only ever read (each one once, into memory, so the hash, the decoded pixels and
the copy all come from the same bytes). Every accepted photo gets a working copy
`images/<frame_id>.jpg` (or `.png` when it has a real alpha channel, which later becomes a mask):
EXIF orientation applied, long side capped, 8-bit RGB(A), no metadata. With `copy_originals` the
original is also copied byte for byte to `originals/<name>` and `ImageRecord.original` is that
relative path; otherwise `original` is the user's absolute path. Relative paths in records are
relative to the capture root.

Decoding goes through Pillow, not cv2.imread: cv2 honours EXIF orientation only with IMREAD_COLOR
(which drops alpha and 16-bit) and decodes a truncated JPEG to a full-size image, grey below the cut,
with nothing but a stderr warning, whereas Pillow's load() raises on truncation. A JPEG is also
checked for its end marker, in case Pillow was told globally to tolerate truncated files.

Near-duplicates: two images whose 32x32 grey thumbnails differ by at most
`near_duplicate_tolerance` grey levels at the 99th percentile of pixels. Measured on the shared
data, re-saved or resized copies (JPEG quality 80 at half size: <= 2; quality 40-60 at full, half
or quarter size: <= 5) against 18 for the closest two of the 67 fox photos and 8 for two lego renders
only half a degree apart. The default 4 catches ordinary re-exports and keeps every distinct view.
"""

from __future__ import annotations

import hashlib
import io
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, Sequence

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_bytes
from lirm.engine.io.images import write_png

from .colour_profiles import source_colour_space, to_srgb
from .exif_exposure import exposure_stops_of_file
from .exif_focal import focal_prior_pixels
from .photo_formats import FORMATS_IN_WORDS, HEIF_SUFFIXES, companion_reason, enable_heif, is_photo, photo_stems, unread_type_reason
from .records import FileReport, ImageRecord

# Files that travel with photos (exports, sidecars, OS litter): skipped without sounding an alarm.
SIDE_FILE_SUFFIXES = {".json", ".txt", ".md", ".csv", ".xmp", ".xml", ".ini", ".db", ".log", ".yaml", ".yml",
                      ".npy", ".npz", ".ply", ".bin", ".pdf", ".html", ".aae", ".thm"}
SIDE_FILE_REASON = "side file, not a photo"
THUMB_SIDE = 32


class Cancelled(Exception):
    """The user cancelled. Everything written so far is complete; `records`/`reports` describe it."""

    def __init__(self, message: str = "cancelled", records: list[ImageRecord] | None = None,
                 reports: list[FileReport] | None = None):
        super().__init__(message)
        self.records = records or []
        self.reports = reports or []


@dataclass
class IngestConfig:
    copy_originals: bool = True
    max_side: int = 1280  # working copies' long side (never upscaled)
    min_side: int = 64  # smaller images cannot be posed or seen; skipped
    jpeg_quality: int = 95
    near_duplicate_tolerance: float | None = 4.0  # grey levels (see the module notes); None: off


Progress = Callable[[int, int], None]
Cancel = Callable[[], bool]


# ---- pieces shared with video_frames -----------------------------------------------------------------

def next_frame_ids(existing: Sequence[ImageRecord]) -> Iterator[str]:
    """"0001", "0002", ... after the largest numeric id already in the capture."""
    taken = {r.frame_id for r in existing}
    n = max((int(r.frame_id) for r in existing if r.frame_id.isdigit()), default=0)
    while True:
        n += 1
        if f"{n:04d}" not in taken:
            yield f"{n:04d}"


def cap_long_side(image: np.ndarray, max_side: int) -> np.ndarray:
    h, w = image.shape[:2]
    scale = max_side / max(h, w)
    if scale >= 1.0:
        return image
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def thumbnail(rgb: np.ndarray) -> np.ndarray:
    """32x32 grey float thumbnail for near-duplicate tests; RGBA is taken over black because the
    colour under transparent pixels is arbitrary."""
    if rgb.ndim == 3 and rgb.shape[2] == 4:
        rgb = (rgb[:, :, :3].astype(np.float32) * (rgb[:, :, 3:4] / 255.0)).astype(np.uint8)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb
    return cv2.resize(grey, (THUMB_SIDE, THUMB_SIDE), interpolation=cv2.INTER_AREA).astype(np.float32)


class ThumbnailIndex:
    """Thumbnails of the images accepted so far, to ask "is this one nearly identical to any of them?"."""

    def __init__(self, tolerance: float | None):
        self.tolerance = tolerance
        self._thumbs = np.zeros((16, THUMB_SIDE * THUMB_SIDE), np.float32)
        self._names: list[str] = []

    @classmethod
    def of_capture(cls, existing: Sequence[ImageRecord], capture_root: Path, tolerance: float | None) -> "ThumbnailIndex":
        """Seeded with the capture's working copies, so that new images are compared with old ones too."""
        index = cls(tolerance)
        if tolerance is None:
            return index
        for record in existing:
            image = cv2.imread(str(Path(capture_root) / record.image), cv2.IMREAD_UNCHANGED)
            if image is None:
                continue  # a missing working copy is the capture folder's problem, not ingest's
            if image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA if image.shape[2] == 4 else cv2.COLOR_BGR2RGB)
            index.add(thumbnail(image), describe(record))
        return index

    def add(self, thumb: np.ndarray, name: str) -> None:
        n = len(self._names)
        if n == len(self._thumbs):
            self._thumbs = np.concatenate([self._thumbs, np.zeros_like(self._thumbs)])
        self._thumbs[n] = thumb.ravel()
        self._names.append(name)

    def find(self, thumb: np.ndarray) -> str | None:
        """The name of an image whose thumbnail differs from `thumb` by at most the tolerance at the
        99th percentile of pixels, or None."""
        if self.tolerance is None or not self._names:
            return None
        diff = np.abs(self._thumbs[: len(self._names)] - thumb.ravel())
        # Cheap first pass: with at most ~1.1% of pixels above the tolerance (each by <= 255), the
        # mean cannot exceed tolerance + 0.011 * 255.
        for i in np.flatnonzero(diff.mean(axis=1) <= self.tolerance + 0.011 * 255):
            if np.percentile(diff[i], 99) <= self.tolerance:
                return self._names[i]
        return None


def describe(record: ImageRecord) -> str:
    """How a report names an accepted image: the user's file name and the frame id."""
    if record.origin == "photo":
        return f"{record.original.name} (frame {record.frame_id})"
    return f"frame {record.frame_id} ({record.origin} at {record.timestamp_s or 0.0:.2f} s)"


def encode_jpeg(rgb: np.ndarray, quality: int) -> bytes:
    ok, encoded = cv2.imencode(".jpg", np.ascontiguousarray(rgb[:, :, ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise OSError("could not encode a JPEG working copy")
    return encoded.tobytes()


def write_working_copy(capture_root: Path, frame_id: str, rgb: np.ndarray, jpeg_quality: int) -> Path:
    """Atomic PNG for RGBA (the alpha is a mask source), JPEG otherwise; returns the relative path."""
    if rgb.ndim == 3 and rgb.shape[2] == 4:
        relative = Path("images") / f"{frame_id}.png"
        write_png(capture_root / relative, rgb)
        return relative
    relative = Path("images") / f"{frame_id}.jpg"
    atomic_write_bytes(capture_root / relative, encode_jpeg(rgb, jpeg_quality))
    return relative


# ---- decoding -------------------------------------------------------------------------------------

class Unreadable(Exception):
    """An input file that is not a complete image; the message is the report's reason."""


def _jpeg_has_end(data: bytes) -> bool:
    """True when the JPEG's end-of-image marker follows its first scan. Walks the marker segments so
    that an EXIF thumbnail's own end marker does not count; data after the end marker (motion photos)
    is fine. Guards truncation even if someone set Pillow's LOAD_TRUNCATED_IMAGES globally."""
    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0xDA:  # start of scan: entropy-coded data cannot contain FF D9 except as the end
            return data.find(b"\xff\xd9", i) >= 0
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    return False


def decode_image(data: bytes, max_side: int) -> tuple[np.ndarray, tuple[int, int], float | None]:
    """Bytes -> (upright 8-bit RGB or RGBA array capped at max_side, upright full size (w, h), the
    EXIF focal length in pixels of that array or None). RGBA only when some pixel is actually
    transparent. Raises Unreadable with the reason."""
    enable_heif()  # by content, not by name: a HEIC saved as .jpg opens too
    try:
        image = Image.open(io.BytesIO(data))
        is_jpeg = image.format in ("JPEG", "MPO")  # MPO: a camera's JPEG with extra pictures appended
        full_w, full_h = image.size
        if is_jpeg and not _jpeg_has_end(data):
            raise Unreadable("the file is cut short (incomplete JPEG)")
        if is_jpeg and max(full_w, full_h) > 2 * max_side:
            # Let libjpeg decode at 1/2, 1/4 or 1/8 scale: big photos decode several times faster.
            f = max_side / max(full_w, full_h)
            image.draft(None, (math.ceil(full_w * f), math.ceil(full_h * f)))
        image.load()
        rgb = cap_long_side(_to_rgb8(image), max_side)
        rgb = to_srgb(rgb, source_colour_space(image))  # a Display P3 or Adobe RGB photo, as sRGB (colour_profiles.py)
    except Unreadable:
        raise
    except Image.DecompressionBombError as err:
        raise Unreadable(f"too large to open safely ({err})") from err
    except UnidentifiedImageError as err:
        raise Unreadable(f"not an image (the contents are not {FORMATS_IN_WORDS})") from err
    except Exception as err:  # Pillow reports damaged files through many exception types
        raise Unreadable(f"corrupt or incomplete image ({err})") from err
    try:
        orientation = int(image.getexif().get(0x0112, 1))
    except Exception:  # damaged EXIF must not cost the photo: it is used as stored
        orientation = 1
    upright = np.ascontiguousarray(apply_orientation(rgb, orientation))
    focal = focal_prior_pixels(image, (full_w, full_h), (upright.shape[1], upright.shape[0]))
    if orientation in (5, 6, 7, 8):
        full_w, full_h = full_h, full_w
    return upright, (full_w, full_h), focal


def apply_orientation(image: np.ndarray, orientation: int) -> np.ndarray:
    """Turn stored pixels upright for an EXIF orientation tag (1-8); applied to the already capped
    array because turning a small array is cheaper than turning the full photo."""
    if orientation == 2:
        return image[:, ::-1]
    if orientation == 3:
        return image[::-1, ::-1]
    if orientation == 4:
        return image[::-1]
    if orientation == 5:  # transpose
        return image.swapaxes(0, 1)
    if orientation == 6:  # stored turned left: turn 90 degrees clockwise
        return np.rot90(image, k=-1)
    if orientation == 7:  # transverse
        return image[::-1, ::-1].swapaxes(0, 1)
    if orientation == 8:
        return np.rot90(image, k=1)
    return image


def _to_rgb8(image: Image.Image) -> np.ndarray:
    if image.mode in ("I;16", "I;16L", "I;16B", "I;16N", "I", "F"):  # 16-bit greyscale PNG
        grey = np.asarray(image, dtype=np.float64)
        grey = np.clip(np.round(grey / 257.0), 0, 255).astype(np.uint8)
        return np.repeat(grey[:, :, None], 3, axis=2)
    has_alpha = image.mode in ("RGBA", "LA", "PA", "RGBa", "La") or "transparency" in image.info
    if has_alpha:
        rgba = np.asarray(image.convert("RGBA"))
        if (rgba[:, :, 3] < 255).any():
            return np.ascontiguousarray(rgba)
    return np.ascontiguousarray(np.asarray(image.convert("RGB")))


# ---- the stage ------------------------------------------------------------------------------------

def ingest_photos(
    inputs: str | Path | Sequence[str | Path],
    capture_root: str | Path,
    config: IngestConfig = IngestConfig(),
    existing: Sequence[ImageRecord] = (),
    progress: Progress | None = None,
    cancel: Cancel | None = None,
) -> tuple[list[ImageRecord], list[FileReport]]:
    """Read a folder (top level only) or a list of files into the capture at `capture_root`.

    Returns the new records (ids continue after `existing`) and one report per input file. Bad
    files are reported and skipped; raises LirmUserError only when `inputs` itself is missing, and
    Cancelled (between files) when cancel() returns True."""
    capture_root = Path(capture_root)
    files, reports = _list_inputs(inputs)
    records: list[ImageRecord] = []
    ids = next_frame_ids(existing)
    by_hash = {r.sha256: describe(r) for r in existing}
    thumbs = ThumbnailIndex.of_capture(existing, capture_root, config.near_duplicate_tolerance)
    used_original_names = {r.original.name for r in existing if not r.original.is_absolute()}
    photo_twins = photo_stems(files)

    total = len(files)
    if progress is not None:
        progress(0, total)
    for done, path in enumerate(files):
        if cancel is not None and cancel():
            raise Cancelled("cancelled while importing photos", records, reports)
        report = FileReport(path=path, accepted=False)
        reports.append(report)
        try:
            report.reason = (companion_reason(path, photo_twins)
                             or _check_and_add(path, capture_root, config, ids, by_hash, thumbs, used_original_names, records, report))
        except Unreadable as err:
            report.reason = str(err)
        if progress is not None:
            progress(done + 1, total)
    return records, reports


def _check_and_add(path, capture_root, config, ids, by_hash, thumbs, used_original_names, records, report) -> str:
    """Process one candidate file; returns the report's reason (empty when accepted)."""
    suffix = path.suffix.lower()
    if path.name.startswith(".") or suffix in SIDE_FILE_SUFFIXES:
        return SIDE_FILE_REASON  # dot files include macOS "._IMG.jpg" resource forks, which are not photos
    if not is_photo(path):
        return unread_type_reason(path)
    if suffix in HEIF_SUFFIXES and not enable_heif():
        return "HEIC / HEIF needs the pillow-heif package (`pip install pillow-heif`), or export the photos as JPEG"
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as err:
        return f"cannot be read ({err.strerror or err})"
    if not data:
        return "empty file (0 bytes): the copy from the camera or card did not finish; copy it again"
    sha = hashlib.sha256(data).hexdigest()
    if sha in by_hash:
        return f"duplicate of {by_hash[sha]}"
    rgb, (full_w, full_h), focal_prior = decode_image(data, config.max_side)
    if min(full_w, full_h) < config.min_side:
        return f"too small ({full_w}x{full_h}; at least {config.min_side} pixels a side are needed)"
    thumb = thumbnail(rgb)
    twin = thumbs.find(thumb)
    if twin is not None:
        return f"nearly identical to {twin}"

    frame_id = next(ids)
    try:
        image_path = write_working_copy(capture_root, frame_id, rgb, config.jpeg_quality)
        if config.copy_originals:
            original = Path("originals") / _free_name(capture_root / "originals", path.name, data, used_original_names)
            if not (capture_root / original).exists():  # an identical copy left by a cancelled run is reused
                atomic_write_bytes(capture_root / original, data)
        else:
            original = path.resolve()
    except OSError as err:
        raise LirmUserError(f"{capture_root}: cannot write into the capture folder ({err}); "
                            "check free disk space and permissions") from err
    record = ImageRecord(frame_id=frame_id, original=original, image=image_path, width=rgb.shape[1], height=rgb.shape[0],
                         sha256=sha, has_alpha=rgb.shape[2] == 4, origin="photo", focal_prior_px=focal_prior,
                         exposure_stops=exposure_stops_of_file(data))
    records.append(record)
    by_hash[sha] = describe(record)
    thumbs.add(thumb, describe(record))
    report.accepted, report.frame_id = True, frame_id
    return ""


def _free_name(folder: Path, name: str, data: bytes, used: set[str]) -> str:
    """`name`, or `stem-2.ext`, ... so that two different files never share a copy; a copy that already
    holds exactly these bytes (from an interrupted run) is reused."""
    stem, suffix = Path(name).stem, Path(name).suffix
    candidate, n = name, 1
    while True:
        target = folder / candidate
        if candidate not in used and (not target.exists() or _same_bytes(target, data)):
            used.add(candidate)
            return candidate
        n += 1
        candidate = f"{stem}-{n}{suffix}"


def _same_bytes(path: Path, data: bytes) -> bool:
    try:
        return path.stat().st_size == len(data) and path.read_bytes() == data
    except OSError:
        return False


def natural_key(path: Path) -> list:
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def _list_inputs(inputs) -> tuple[list[Path], list[FileReport]]:
    """Candidate files in import order, and reports for what is not even a candidate."""
    reports: list[FileReport] = []
    if isinstance(inputs, (str, Path)):
        folder = Path(inputs)
        if folder.is_file():
            return [folder], reports
        if not folder.is_dir():
            raise LirmUserError(f"{folder}: no such folder or file; choose the folder that holds the photos")
        files = []
        for entry in sorted(folder.iterdir(), key=natural_key):
            if entry.is_dir():
                if not entry.name.startswith("."):
                    reports.append(FileReport(entry, False, "a folder: only the photos directly inside are imported"))
            else:
                files.append(entry)
        return files, reports
    files = []
    for item in inputs:
        path = Path(item)
        if path.is_file():
            files.append(path)
        else:
            reports.append(FileReport(path, False, "not found" if not path.exists() else "not a file"))
    return files, reports
