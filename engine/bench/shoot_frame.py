"""The similarity from a capture's frame to the frame a `lirm demo` shoot was rendered in, found from
the camera centres (the capture's photos matched to the shoot's true cameras by file name). The
lighting bench turns the estimated lighting by it; the relight bench places the export with it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.capture.alignment import similarity_align
from lirm.engine.errors import LirmUserError


def shoot_similarity(capture, truth_file: dict, moved_by: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """(scale, rotation, translation) with shoot ≈ scale * rotation @ capture + translation; `moved_by`:
    a 4x4 similarity the capture's cameras are moved by first (an export's placement)."""
    truth_cameras = {Path(f["file_path"]).stem: Camera.from_dict(f) for f in truth_file["frames"]}
    pairs = []
    for frame_id, state in capture.frames.items():
        stem = state.record.original.stem
        if frame_id in capture.cameras and stem in truth_cameras:
            camera = capture.cameras[frame_id]
            pairs.append(((camera if moved_by is None else camera.moved_by(moved_by)).center, truth_cameras[stem].center))
    if len(pairs) < 3:
        raise LirmUserError(f"{capture.root}: only {len(pairs)} of the capture's posed photos are in the shoot's "
                            f"truth/transforms.json; its frame cannot be aligned to the shoot's")
    return similarity_align(np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
