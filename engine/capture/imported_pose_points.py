"""Sparse points for a capture whose poses were imported from a transforms.json.

A transforms.json holds cameras and nothing else, yet the automatic masks are seeded by sparse points
on the object (auto_mask.py): without any, twelve fox photos posed by its own transforms.json came out
with twelve empty masks, and the capture had nothing to reconstruct. So when the masks are to be
automatic, COLMAP is run on the same photos for its points alone: its own cameras are aligned to the
imported ones by a similarity over the camera centres of the frames both posed (Umeyama), and its
points and their observations are carried into the imported frame. The imported cameras are kept as
they are: they are what the user gave.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .alignment import apply_similarity, similarity_align
from .records import PosingResult

# The aligned COLMAP camera centres must land within this share of the imported cameras' spread
# (their RMS distance from their mean) for its points to be trusted in the imported frame.
MAX_ALIGNMENT_ERROR = 0.05


def points_in_imported_frame(imported: PosingResult, colmap: PosingResult) -> tuple[PosingResult, str]:
    """`imported` with COLMAP's points (and each frame's observations) moved into its frame, and a
    sentence for the capture log; `imported` unchanged, and the reason, when the two cannot be aligned
    (fewer than 3 frames posed by both, or centres that do not agree after the similarity)."""
    shared = sorted(set(imported.cameras) & set(colmap.cameras))
    if len(colmap.points) == 0:
        return imported, "COLMAP found no sparse points in these photos"
    if len(shared) < 3:
        return imported, f"COLMAP posed {len(shared)} of the imported frames (3 are needed to align its points)"
    source = np.array([colmap.cameras[f].center for f in shared])
    target = np.array([imported.cameras[f].center for f in shared])
    try:
        scale, rotation, translation = similarity_align(source, target)
    except ValueError as error:
        return imported, f"COLMAP's cameras cannot be aligned to the imported ones ({error})"
    aligned = apply_similarity(scale, rotation, translation, source)
    spread = float(np.sqrt(np.mean(np.sum((target - target.mean(axis=0)) ** 2, axis=1))))
    error = float(np.sqrt(np.mean(np.sum((aligned - target) ** 2, axis=1)))) / max(spread, 1e-12)
    if error > MAX_ALIGNMENT_ERROR:
        return imported, (f"COLMAP's cameras disagree with the imported ones by {error:.0%} of their spread after "
                          f"alignment (at most {MAX_ALIGNMENT_ERROR:.0%} is trusted)")
    points = apply_similarity(scale, rotation, translation, np.asarray(colmap.points, dtype=np.float64).reshape(-1, 3))
    observations = {f: v for f, v in colmap.observations.items() if f in imported.cameras}
    result = replace(imported, points=points, point_colors=colmap.point_colors, observations=observations)
    return result, (f"{len(points)} sparse points from COLMAP, aligned to the imported cameras over {len(shared)} "
                    f"frames (centres within {error:.1%} of their spread)")
