"""Which photo files a capture reads, and what the user is told about the ones it does not.

Every accepted photo becomes an 8-bit JPEG or PNG working copy at ingest, so a format only has to
decode once, here; nothing after ingest sees the original's format.

- JPEG, PNG, TIFF (16-bit TIFFs from a raw developer are reduced to 8 bits), WebP and BMP decode
  through Pillow.
- HEIC / HEIF, the iPhone's default since 2017, decode through pillow-heif. It turns the pixels
  upright by the file's own transform and resets the EXIF orientation to 1, so ingest never turns a
  HEIC twice; a 10-bit (HDR) HEIC comes out as 8 bits.
- Camera raw files are not developed here: white balance, demosaicing and a tone curve are a raw
  developer's choices, and the capture's lighting reads photos as display-referred pictures. A raw
  file beside a photo of the same name (a camera set to RAW + JPEG) is a side file and its photo is
  used; a raw file alone is skipped with the fix. The clip of an iPhone's Live Photo beside its photo
  is skipped as such (a video is captured on its own: `lirm capture VIDEO`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png", ".tif", ".tiff", ".webp", ".bmp", ".heic", ".heif")
HEIF_SUFFIXES = (".heic", ".heif")
RAW_SUFFIXES = frozenset({".dng", ".cr2", ".cr3", ".crw", ".nef", ".nrw", ".arw", ".srf", ".sr2", ".raf", ".orf",
                          ".rw2", ".pef", ".srw", ".x3f", ".3fr", ".iiq", ".rwl", ".erf", ".kdc", ".mrw", ".raw"})
VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v")
LIVE_PHOTO_SUFFIXES = frozenset({".mov", ".mp4"})  # an iPhone's Live Photo: IMG_0001.HEIC with IMG_0001.MOV
FORMATS_IN_WORDS = "JPEG, PNG, TIFF, WebP, BMP or HEIC"

_heif_ready: bool | None = None


def enable_heif() -> bool:
    """Let Pillow open HEIC / HEIF files (once per process); False when pillow-heif is missing."""
    global _heif_ready
    if _heif_ready is None:
        try:
            import pillow_heif
        except ImportError:
            _heif_ready = False
        else:
            pillow_heif.register_heif_opener()
            _heif_ready = True
    return _heif_ready


def is_photo(path: Path) -> bool:
    return path.suffix.lower() in PHOTO_SUFFIXES and not path.name.startswith(".")


def photo_stems(paths: Iterable[Path]) -> set[tuple[Path, str]]:
    """(folder, lower-case stem) of every photo among `paths`: what a raw file's twin is looked up in."""
    return {(p.parent, p.stem.lower()) for p in paths if is_photo(p)}


def companion_reason(path: Path, stems: set[tuple[Path, str]]) -> str | None:
    """The report's reason for a camera raw file, or for a Live Photo's clip beside its photo; None
    when `path` is neither."""
    suffix = path.suffix.lower()
    if path.name.startswith(".") or suffix not in RAW_SUFFIXES | LIVE_PHOTO_SUFFIXES:
        return None
    twin = (path.parent, path.stem.lower()) in stems
    if suffix in LIVE_PHOTO_SUFFIXES:  # a video alone is not a companion: the folder's report says what it is
        return "a Live Photo's clip beside its photo of the same name: the photo is used" if twin else None
    if twin:
        return "camera raw beside its photo of the same name (RAW + JPEG): the photo is used"
    return (f"camera raw ({path.suffix.upper().lstrip('.')}) is not developed here: use the camera's JPEG, or "
            f"export the raw files as JPEG or 16-bit TIFF from a raw developer and import those")


def unread_type_reason(path: Path) -> str:
    """The report's reason for a file type that is neither a photo, a raw file nor a known side file."""
    suffix = path.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return f"a video among photos: a video is captured on its own (`lirm capture {path}`)"
    if suffix in (".avif", ".jxl", ".gif", ".psd", ".exr", ".hdr"):
        return f"{suffix.lstrip('.').upper()} is not read here; save the photo as {FORMATS_IN_WORDS}"
    return f"not an image type we read ({FORMATS_IN_WORDS})"


def folders_with_photos(root: Path, max_depth: int = 3, max_entries: int = 5000) -> list[tuple[Path, int]]:
    """The folders below `root` (not `root` itself) that hold photos, with how many, nearest first:
    what to name when a user points at a folder whose photos are in subfolders (a phone's DCIM/100APPLE,
    an export by date). Hidden folders and links are not followed; at most `max_entries` entries are
    looked at, so that pointing at a home folder cannot stall the message. Each folder is listed once."""
    found: list[tuple[Path, int]] = []
    level, seen = [root], 0
    for depth in range(max_depth + 1):  # depth 0 is `root` itself, listed only for its subfolders
        below: list[Path] = []
        for folder in level:
            try:
                entries = sorted(folder.iterdir())
            except OSError:  # unreadable: nothing to name there
                continue
            seen += len(entries)
            count = sum(1 for p in entries if is_photo(p) and p.is_file())
            if depth > 0 and count:
                found.append((folder, count))
            below.extend(e for e in entries if not e.name.startswith(".") and not e.is_symlink() and e.is_dir())
            if seen > max_entries:
                return found
        level = below
    return found
