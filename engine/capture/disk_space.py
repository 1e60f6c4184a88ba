"""Free disk space checked before each capture stage, so that a full disk stops the capture with a
sentence and a resumable folder instead of an abort inside COLMAP (which leaves its database's
-wal/-shm files behind).

The estimates are deliberately generous upper bounds of what each stage writes (measured on the
fox and demo captures: working PNGs about 1.5 bytes a pixel, the COLMAP database about 1.5 MB per
1000 px photo, masks well under a byte a pixel, a prepared crop about 40 bytes a pixel of its side
squared), plus a fixed reserve so the rest of the system is not starved."""

from __future__ import annotations

import shutil
from pathlib import Path

from lirm.engine.errors import LirmResourceError

RESERVE_BYTES = 64 * 2**20


def stage_bytes(stage: str, photos: int, long_side: int, crop_size: int, input_bytes: int = 0) -> int:
    """Upper bound of the bytes `stage` writes for `photos` photos of `long_side` pixels."""
    pixels = long_side * long_side * 3 // 4  # a 4:3 photo
    if stage == "ingest":
        return input_bytes + photos * pixels * 3  # originals copied, working PNGs (about 1.5 B/px; room for RGBA)
    if stage == "pose":
        return photos * (4 * 2**20 + pixels * 3)  # database, model files and undistorted copies
    if stage == "masks":
        return photos * pixels
    if stage == "crops":
        return photos * crop_size * crop_size * 48
    return 0


def require_free_space(folder: str | Path, needed: int, what: str) -> None:
    """Raise LirmResourceError unless `folder`'s filesystem has `needed` bytes (plus a reserve) free."""
    folder = Path(folder)
    probe = folder if folder.exists() else folder.parent
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    free = shutil.disk_usage(probe).free
    if free < needed + RESERVE_BYTES:
        raise LirmResourceError(
            f"{folder}: not enough free disk space to {what}: it needs about {_mb(needed + RESERVE_BYTES)}, "
            f"{_mb(free)} are free. Free some space (or move the capture to a larger disk) and run "
            f"`lirm capture --resume {folder}` to go on from here")


def _mb(n: int) -> str:
    return f"{n / 2**20:.0f} MB" if n < 2**30 else f"{n / 2**30:.1f} GB"
