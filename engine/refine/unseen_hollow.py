"""The hollow under an opening that the photos see into but not down: a mug's inside continued to its floor.

Photos taken from above an open container see its opening's upper part only: from 30 degrees of
elevation a view reaches into a mug about half its width down the far wall, and the plane sweep
(photo_carving.py), which needs two neighbours to see a point too, carves less than that. Below
what it carved, the masks' hull stays solid: a false floor a third of the way down, which the fit
then keeps (README, "What the photos see through the hull"). Nothing in the photos says where
the real floor is; what a user expects of a cup, a bowl or a vase is a wall of even thickness
round an inside that goes down to a floor about that thick above the base.

The prior: where the carved opening's bottom is not a surface the photos saw (few of its voxels
hold a matched point; a bowl of soil or a shallow tray whose floor they do see holds many, and is
left as it is), the inside continues straight down from it, keeping a wall as thick as the walls
the photos did see round the opening (the hull's voxels beside the carved space, their distance to
the hull's outside), and stopping that thick above the lowest outer surface the photos saw (not the
hull's bottom: the wedge the masks leave under an object seen from above reaches far below it).
It only ever removes, and only below a carved opening, where no photo looked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .photo_carving import PhotoCarving

__all__ = ["UnseenHollowConfig", "UnseenHollow", "hollow_below_opening"]


@dataclass(frozen=True)
class UnseenHollowConfig:
    min_bottom_voxels: int = 27  # a carved bottom smaller than this (a dent, a crook) says nothing about an inside
    max_seen_share: float = 0.5  # a bottom more of whose voxels hold (or touch) a matched point is a floor the photos saw
    min_wall_voxels: float = 1.5  # the wall kept is at least this thick
    floor_quantile: float = 0.005  # the lowest outer surface the photos saw: this quantile of its heights
    min_floor_points: int = 20  # fewer matched outer-surface voxels than this place no floor
    up_axis: int = 2  # the world's up (+Z, DESIGN.md): occupancy[..., k] grows upward with k
    open_neighbours: int = 6  # a voxel inside the walls with this many of its 8 neighbours across open goes too
    closing_passes: int = 3  # ... repeated this often (a pillar up to about twice as wide)


@dataclass
class UnseenHollow:
    """What the prior did, for the refinement's notes and the README."""

    occupancy: np.ndarray  # (R, R, R) bool: the carved hull with the hollow removed
    hollowed_voxels: int
    wall_voxels: float  # the wall thickness kept (voxels); NaN when nothing was measured
    seen_bottom_share: float  # of the carved opening's bottom, the share the photos matched (NaN: none)
    why_not: str = ""  # why nothing was hollowed ("" when something was)
    # (R, R, R) bool: the hollow less its outermost voxel across, what a hull carved by voxel centres
    # (a voxel thinner than the one hollowed) loses: its walls would be a voxel thin, which the hull's
    # signed distance (smoothed) does not hold, and a refinement started from it started empty.
    core: np.ndarray | None = None

    def sentence(self) -> str:
        if self.why_not:
            return f"the opening's inside is not continued down: {self.why_not}"
        return (f"the opening's inside continued down to a floor no photo saw: {self.hollowed_voxels} voxels under "
                f"it hollowed, keeping walls {self.wall_voxels:.1f} voxels thick (the photos matched "
                f"{100 * self.seen_bottom_share:.0f}% of the carved space's bottom)")


def hollow_below_opening(hull: np.ndarray, carving: PhotoCarving,
                         config: UnseenHollowConfig = UnseenHollowConfig()) -> UnseenHollow:
    """`hull`: the (R, R, R) occupancy the carving started from; `carving`: what it did (its
    `seen_surface` needed). Returns the carving's occupancy less the hollow."""
    hull = np.asarray(hull, bool)
    kept = np.asarray(carving.occupancy, bool)
    nan = float("nan")
    if carving.seen_surface is None:
        raise ValueError("the carving did not record the surface its photos matched (PhotoCarving.seen_surface)")
    # Everything below is worked with the up axis last.
    up = config.up_axis
    hull, kept, seen = (np.moveaxis(a, up, -1) for a in (hull, kept, np.asarray(carving.seen_surface, bool)))
    removed = hull & ~kept

    def result(occupancy: np.ndarray, wall: float, share: float, why: str) -> UnseenHollow:
        hollow = kept & ~occupancy
        core = hollow & ndimage.binary_erosion(hollow | removed, np.ones((3, 3, 1), bool), border_value=1)
        return UnseenHollow(np.moveaxis(occupancy, -1, up).copy(), int(hollow.sum()), wall, share, why,
                            np.moveaxis(core, -1, up).copy())

    if not removed.any():
        return result(kept, nan, nan, "the carving removed nothing")
    depth = ndimage.distance_transform_edt(hull)  # voxels to the hull's outside
    across = ndimage.generate_binary_structure(2, 1)[..., None]  # the 4 neighbours across (not above or below)
    walls = kept & ndimage.binary_dilation(removed, across)  # kept voxels next to the carved space
    seen_walls = walls & seen
    measured = seen_walls if seen_walls.sum() >= config.min_floor_points else walls
    wall = max(float(np.median(depth[measured])), config.min_wall_voxels) if measured.any() else config.min_wall_voxels
    inside = depth > wall
    above_removed = np.zeros_like(removed)
    above_removed[..., :-1] = removed[..., 1:]
    bottom = kept & inside & above_removed
    if bottom.sum() < config.min_bottom_voxels:
        return result(kept, wall, nan, f"the carved space has no inside to continue ({int(bottom.sum())} voxels of "
                                          f"bottom {wall:.1f} voxels or more inside the walls)")
    share = float((bottom & ndimage.binary_dilation(seen)).sum() / bottom.sum())
    if share > config.max_seen_share:
        return result(kept, wall, share, f"the photos saw its bottom ({100 * share:.0f}% of it matched): a floor")
    skin = seen & (depth <= 1.5)
    if skin.sum() < config.min_floor_points:
        return result(kept, wall, share, f"too little of the outer surface was matched ({int(skin.sum())} voxels) "
                                            f"to place a floor by")
    lowest_seen = float(np.quantile(np.nonzero(skin)[2], config.floor_quantile))
    lowest_hollow = max(int(np.ceil(lowest_seen + wall + 0.5)), 0)
    hollow = np.zeros_like(kept)
    for k in range(kept.shape[-1] - 2, lowest_hollow - 1, -1):
        hollow[..., k] = kept[..., k] & inside[..., k] & (hollow[..., k + 1] | removed[..., k + 1])
    # Columns under a patch the carving left (a plain spot of the inside: no evidence) stand as
    # pillars in the hollow; one whose neighbours across are nearly all open goes with them.
    allowed = kept & inside
    allowed[..., :lowest_hollow] = False
    ring = np.ones((3, 3, 1), np.float32)
    ring[1, 1, 0] = 0.0
    for _ in range(config.closing_passes):
        open_around = ndimage.convolve((hollow | removed).astype(np.float32), ring, mode="constant")
        grown = allowed & ~hollow & (open_around >= config.open_neighbours)
        if not grown.any():
            break
        hollow |= grown
    return result(kept & ~hollow, wall, share, "" if hollow.any() else "nothing lies under the opening")
