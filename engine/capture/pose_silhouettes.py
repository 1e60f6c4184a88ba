"""Poses against silhouettes: views that structure from motion put on the wrong side of the object.

An object that looks alike from opposite sides (the lego's base plate, a grid of studs, seen from
front and back; a vase's pattern) can fool COLMAP: it registers a view with matches to the other
side, and the model it reports is consistent with itself. On the lego's 50 renders on white it
placed 14 of the 44 views it registered 172-175 degrees from their true direction, and nothing in its
own statistics said so. The object's outline in each photo does: a visual hull carved from the
views that are right projects into a wrong view somewhere else than its outline, and a wrong view
cuts the hull where the others see object.

Where the outlines can be trusted without the poses (a plain backdrop's outline, plain_backdrop.py,
or the photos' alpha), the views are checked greedily: carve the hull from the views still kept
(tolerant, as the masks' own hull: a voxel stays when 85% of the views that see it agree), measure
for each the share of its outline outside the hull's projection, and leave out the worst while
that share is above `max_outside`. On the lego the 14 wrong views went first, one by one, then
every view kept had under 1% outside while the 14 had 14-34%. When that would leave out
`max_left_out` of the views or more, no majority agrees and nothing is left out (the poses are
reported as they are).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.capture.visual_hull import carve_visual_hull, project_hull

__all__ = ["PoseSilhouetteConfig", "views_against_silhouettes"]


@dataclass(frozen=True)
class PoseSilhouetteConfig:
    enabled: bool = True
    resolution: int = 64
    # As the automatic masks' hull: one view's imperfect outline must not cut it.
    min_views_fraction: float = 0.85
    # A view whose outline lies more than this share outside the other views' hull is left out.
    max_outside: float = 0.1
    # Leaving out this share of the views or more: no majority agrees, leave out none.
    max_left_out: float = 0.45


def _outside_share(hull, outline: np.ndarray, camera: Camera) -> float:
    inside = outline > 0
    area = np.count_nonzero(inside)
    if area == 0:
        return 0.0
    return float(np.count_nonzero(inside & (project_hull(hull, camera) == 0))) / area


def views_against_silhouettes(
    outlines: Mapping[str, np.ndarray],
    cameras: Mapping[str, Camera],
    radius: float,
    config: PoseSilhouetteConfig = PoseSilhouetteConfig(),
    cancelled: Callable[[], bool] | None = None,
    already_left_out: int = 0,
) -> dict[str, float]:
    """Views to leave out: frame id -> share of its outline outside the hull of the views kept, in
    the order they were left out (see the module docstring). Empty when every view agrees, when no
    majority does, or with fewer than 5 views. outlines: frame id -> uint8 or bool image at its
    camera's size, non-zero on the object; cameras: the object inside `radius` around the origin.
    already_left_out: views an earlier round left out, counted against `max_left_out`."""
    frames = [f for f in outlines if f in cameras]
    if not config.enabled or len(frames) < 5:
        return {}
    kept = list(frames)
    left_out: dict[str, float] = {}
    while len(kept) > 4:
        if cancelled is not None and cancelled():
            break
        hull = carve_visual_hull({f: outlines[f] for f in kept}, {f: cameras[f] for f in kept}, radius=radius,
                                 resolution=config.resolution, min_views_fraction=config.min_views_fraction,
                                 within_sphere=True)
        if hull.is_empty:
            return {}
        shares = {f: _outside_share(hull, outlines[f], cameras[f]) for f in kept}
        worst = max(kept, key=lambda f: shares[f])
        if shares[worst] <= config.max_outside:
            break
        if already_left_out + len(left_out) + 1 >= config.max_left_out * (len(frames) + already_left_out):
            return {}
        left_out[worst] = shares[worst]
        kept.remove(worst)
    return left_out
