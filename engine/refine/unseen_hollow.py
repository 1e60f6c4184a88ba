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
left as it is), the inside continues down from it, layer by layer, across the whole of the
opening's outline (the carved space's footprint filled out to its convex hull: the carving empties
only the patches the photos matched), keeping a wall as thick as the walls the photos did see round
the opening (the hull's voxels beside the carved space, their distance to the hull's outside) and a
voxel more, and stopping that thick (or 6% of the height) above the base: the lowest outer surface
the photos saw, or lower where the hull keeps its width (not the hull's bottom: the wedge the masks
leave under an object seen from above reaches far below it). The lid the hull keeps over the
opening goes too. It only ever removes, and only round a carved opening, where no photo looked.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
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
    # The base then walked down while each layer of the hull keeps this share of the cross-section of
    # the one above: the photos of a plain lower body match little of it (the synthetic mugs' lowest
    # matched skin stood 5-7 voxels above their base), but the masks' hull keeps the object's width
    # down to its base and narrows at once below it, in the wedge the views leave (by 5-12% a layer
    # on the synthetic mugs, the demo's and the tests' cups, 0-3% above it)
    base_area_share: float = 0.95
    # The floor kept over the base: as thick as the walls, or this share of the height if more (a mug's
    # is often thicker than its walls: the demo's about 6% of its height)
    floor_height_share: float = 0.06
    min_floor_points: int = 20  # fewer matched outer-surface voxels than this place no floor
    # The hollow keeps this much more wall (voxels) than the walls measured round the carved space:
    # the footprint hull is up to a voxel fatter than the object in places, and without it the demo
    # mug's hollow took 3692 voxels of its true walls (381 with it; 488 when it went only down the
    # carved columns, which hollowed 59-66% of the synthetic mugs' insides against 90-94% now)
    lateral_margin_voxels: float = 1.0
    up_axis: int = 2  # the world's up (+Z, DESIGN.md): occupancy[..., k] grows upward with k


@dataclass
class UnseenHollow:
    """What the prior did, for the refinement's notes and the README."""

    occupancy: np.ndarray  # (R, R, R) bool: the carved hull with the hollow removed
    hollowed_voxels: int
    wall_voxels: float  # the walls' thickness round the carved space (voxels); NaN when nothing was measured
    seen_bottom_share: float  # of the carved opening's bottom, the share the photos matched (NaN: none)
    why_not: str = ""  # why nothing was hollowed ("" when something was)
    margin_voxels: float = 0.0  # the wall the hollow kept is this much thicker than wall_voxels
    # (R, R, R) bool: the hollow less its outermost voxel across, what a hull carved by voxel centres
    # (a voxel thinner than the one hollowed) loses: its walls would be a voxel thin, which the hull's
    # signed distance (smoothed) does not hold, and a refinement started from it started empty.
    core: np.ndarray | None = None

    def sentence(self) -> str:
        if self.why_not:
            return f"the opening's inside is not continued down: {self.why_not}"
        return (f"the opening's inside continued down to a floor no photo saw: {self.hollowed_voxels} voxels under "
                f"it hollowed, keeping walls {self.wall_voxels + self.margin_voxels:.1f} voxels thick (the photos matched "
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
                            config.lateral_margin_voxels, np.moveaxis(core, -1, up).copy())

    if not removed.any():
        return result(kept, nan, nan, "the carving removed nothing")
    depth = ndimage.distance_transform_edt(hull)  # voxels to the hull's outside
    sideways = ndimage.generate_binary_structure(2, 1)[..., None]  # the 4 neighbours across (not above or below)
    walls = kept & ndimage.binary_dilation(removed, sideways)  # kept voxels next to the carved space
    seen_walls = walls & seen
    measured = seen_walls if seen_walls.sum() >= config.min_floor_points else walls
    wall = max(float(np.median(depth[measured])), config.min_wall_voxels) if measured.any() else config.min_wall_voxels
    inside = depth > wall
    # Across (within each layer): near the hull's top, its distance to the outside is the lid's, not the walls'
    across = ndimage.distance_transform_edt(hull, sampling=(1.0, 1.0, float(hull.shape[-1])))
    lateral = across > wall + config.lateral_margin_voxels
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
    base = min(lowest_seen, _base_below(hull, int(np.floor(lowest_seen)), config.base_area_share))
    height = float(np.nonzero(hull.any(axis=(0, 1)))[0].max()) - base
    lowest_hollow = max(int(np.ceil(base + max(wall, config.floor_height_share * height) + 0.5)), 0)
    # Down from the carved space, layer by layer: the parts of a layer inside the walls and under the
    # opening's outline that touch what is open above. The carving empties only the patches the photos
    # matched through the opening; under a plain patch, or the side of the opening no view looked down,
    # columns stood as pillars and walls twice as thick (the synthetic mug's inside, 59% hollowed).
    opening = _opening_outline(removed.any(axis=-1))
    hollow = np.zeros_like(kept)
    for k in range(kept.shape[-1] - 2, lowest_hollow - 1, -1):
        candidates = kept[..., k] & lateral[..., k] & opening
        parts, _ = ndimage.label(candidates)
        touched = np.unique(parts[candidates & (hollow[..., k + 1] | removed[..., k + 1])])
        hollow[..., k] = np.isin(parts, touched[touched > 0])
    hollow |= _cap_over(hull, kept & ~hollow, removed | hollow, seen, opening, wall + config.lateral_margin_voxels)
    return result(kept & ~hollow, wall, share, "" if hollow.any() else "nothing lies under the opening")


def _cap_over(hull: np.ndarray, kept: np.ndarray, opened: np.ndarray, seen: np.ndarray, opening: np.ndarray,
              wall: float) -> np.ndarray:
    """The lid the masks' hull keeps over what was opened (up axis last): in the columns of the
    opening's outline whose highest opened voxel lies at most `wall` and a voxel below the hull's top,
    the kept voxels above it, up to the first the photos matched (a wall's top, which no opened voxel
    comes near, stays; over a cup the masks' hull is a dome of air, too narrow across for a wall
    test). The sweep carves nothing within two voxels of the hull's surface (its matches there are
    the surface's own), so over the synthetic mugs' openings the hull's top stayed, 3-4 voxels with
    the sampling's slack, and the fit closed the opening with it: a lid the photos look through."""
    resolution = kept.shape[-1]
    layers = np.arange(resolution)[None, None, :]
    has_opened = opened.any(axis=-1)
    highest, top = _highest_layer(opened), _highest_layer(hull)
    columns = opening & has_opened & (top - highest <= wall + 1.0)
    above = layers > highest[..., None]
    below_a_match = np.cumsum(seen & above, axis=-1) > 0
    return kept & above & ~below_a_match & columns[..., None]


def _highest_layer(occupancy: np.ndarray) -> np.ndarray:
    """(R, R) int: each column's highest occupied layer (up axis last); 0 in an empty column."""
    resolution = occupancy.shape[-1]
    return np.where(occupancy.any(axis=-1), resolution - 1 - np.argmax(occupancy[..., ::-1], axis=-1), 0)


def _opening_outline(footprint: np.ndarray) -> np.ndarray:
    """(R, R) bool: the opening's outline seen from above, from the carved space's footprint (patches
    where the photos matched through it, with gaps between): its largest part, closed across gaps
    of a few voxels, and filled out to its convex hull."""
    closed = ndimage.binary_closing(footprint, iterations=2, border_value=0) | footprint
    parts, count = ndimage.label(closed)
    if count == 0:
        return closed
    largest = parts == 1 + int(np.argmax(ndimage.sum_labels(closed, parts, range(1, count + 1))))
    points = np.argwhere(largest)[:, ::-1].astype(np.int32)  # (x = column, y = row) for OpenCV
    outline = np.zeros(footprint.shape, np.uint8)
    cv2.fillConvexPoly(outline, cv2.convexHull(points), 1)
    return outline.astype(bool) | largest


def _base_below(hull: np.ndarray, start: int, share: float) -> int:
    """The object's base (a layer, up axis last): from `start` down while each layer's cross-section is
    at least `share` of the one above it."""
    area = hull.sum(axis=(0, 1))
    k = start
    while k > 0 and area[k - 1] >= share * area[k] and area[k] > 0:
        k -= 1
    return k
