"""Plain records passed between the capture stages (ingest -> pose -> normalise -> mask -> crop).

Frame ids are stable strings chosen at ingest ("0001", "0002", ...); every later stage and the
capture folder's files refer to frames by id, never by list position, so adding photos or re-posing
keeps each frame's identity.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lirm.engine.cameras import Camera


@dataclass
class FileReport:
    """What happened to one input file, for the per-file report the user sees."""

    path: Path
    accepted: bool
    reason: str = ""  # why it was skipped, or a note ("duplicate of 0003.jpg")
    frame_id: str | None = None


@dataclass
class ImageRecord:
    """One accepted image. `image` is the working copy inside the capture (EXIF orientation applied,
    long side capped), relative to the capture root; `original` is where the user's file is."""

    frame_id: str
    original: Path
    image: Path
    width: int
    height: int
    sha256: str  # of the original file's bytes
    has_alpha: bool = False
    origin: str = "photo"  # photo | video | camera
    timestamp_s: float | None = None  # for video and camera frames
    focal_prior_px: float | None = None  # the lens's focal length from EXIF, in working-copy pixels (exif_focal.py)
    exposure_stops: float | None = None  # log2(time x ISO / 100 / f-number^2) from EXIF (exif_exposure.py)


@dataclass
class PosingResult:
    """Cameras in the pose source's own world frame (COLMAP's or the imported file's)."""

    cameras: dict[str, Camera]  # frame id -> camera, for the registered frames only
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (N, 3) sparse points
    point_colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.uint8))  # (N, 3) RGB
    status: dict[str, str] = field(default_factory=dict)  # frame id -> "registered" or why not
    source: str = "colmap"  # colmap | transforms.json | colmap-model
    # Per frame, the sparse point indices it observes (for mask seeding); optional.
    observations: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def registered(self) -> list[str]:
        return sorted(self.cameras)
