"""Make the normalised world hold the whole object, as the photos' masks outline it.

Normalisation sizes the object from its sparse SfM points (normalize.py), before any mask exists.
A part without points is invisible to it: the WaterBottle's dark, smooth cap carries none, so the
points' top stops at the bottle's shoulder and the cap rises out of the ball of radius R (its masks'
hull reaches 1.07-1.16 R above the origin on three shoots), out of the model's [-R, R]^3 box, and a
reconstruction would cut it off.

Once the masks exist, their visual hull bounds the object from above, however few points a part
has. When an object standing on a support plane rises above the ball, the world is re-fitted to the
hull as normalize.py fits it to points: centre on the plane's normal through the current centre,
half-way between the plane and the hull's top, radius a high percentile of the hull's distances
from it (at least half its height), mapped to `fill * R`. An object that already fits is left
exactly as it was: the hull is one voxel fatter than the object and bulges where a ring of views
cannot carve (the middle of a flat top, by up to its half-width times the tangent of the views'
elevation; a mug's rim), so it is a check that the object fits, not a better size. The bulge can
make the check fire for an object whose top is just under R; the re-fit then leaves it more room,
never less. An object taller than the masks' search ball (R / fill) is brought in only as far as
that ball lets the hull see it.

A capture with no sparse points at all (poses imported from a transforms.json, masks from alpha or a
folder) was sized by normalize.py from the cameras alone, a guess that the object fills half the
view: the NeRF lego (20 views) came out 1.8 times too large for the ball, its base plate cut round by
it. There the masks are the only measure of the object, so its hull sizes the world outright
(`size_world_from_silhouettes`): carved first in a ball reaching toward the nearest camera, then
again, finer, in the ball the masks are searched in, each time centred on the middle of the hull's
extent and scaled so that its farthest voxel lands at `fill * R`.

Masks are pixels and do not move; cameras, points and the support plane are moved by the same
similarity, recorded in the capture's normalisation so exports still undo it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.capture.masks import check_mask
from lirm.engine.capture.normalize import Normalization, is_floor
from lirm.engine.capture.visual_hull import VOXEL_HALF_DIAGONAL, carve_visual_hull, cut_below_plane

__all__ = ["SilhouetteFitConfig", "SilhouetteFit", "fit_world_to_silhouettes", "size_world_from_silhouettes", "moved_camera",
           "moved_normalization"]


@dataclass(frozen=True)
class SilhouetteFitConfig:
    resolution: int = 80
    # As the automatic masks' own hull: one view's bad mask must not cut the hull.
    min_views_fraction: float = 0.85
    radius_percentile: float = 95.0


@dataclass
class SilhouetteFit:
    """What the check found: the hull's top above the origin (along the plane's normal), and the
    similarity applied (x -> scale * (x - shift)); scale 1 and shift 0 when the object fitted."""

    top: float
    scale: float
    shift: np.ndarray

    @property
    def moved(self) -> bool:
        return self.scale != 1.0 or bool(np.any(self.shift != 0.0))


def fit_world_to_silhouettes(
    masks: dict[str, np.ndarray],
    cameras: dict[str, Camera],
    normalization: Normalization,
    target_radius: float,
    fill: float,
    search_radius: float,
    config: SilhouetteFitConfig = SilhouetteFitConfig(),
) -> SilhouetteFit | None:
    """The similarity that makes the masks' hull fit the ball of `target_radius` (see the module
    docstring), or None when there is nothing to check: no floor under the object (no plane, or a
    wall), fewer than 3 usable masks or an empty hull. `search_radius` bounds the carving (the masks were searched in that ball)."""
    if not is_floor(normalization.plane):
        # Only a floor: views of an object on a wall all look from its front, cannot carve its depth
        # toward them, and the hull's distance from the wall says little about the object's.
        return None
    usable = {f: m for f, m in masks.items() if f in cameras and check_mask(m) is None}
    if len(usable) < 3:
        return None
    hull = carve_visual_hull(usable, {f: cameras[f] for f in usable}, radius=search_radius,
                             resolution=config.resolution, min_views_fraction=config.min_views_fraction,
                             within_sphere=True)
    cut_below_plane(hull, normalization.plane)
    if hull.is_empty:
        return None
    normal, offset = np.asarray(normalization.plane[0], dtype=np.float64), float(normalization.plane[1])
    centers = hull.occupied_centers()
    heights = centers @ normal - offset
    top_height = float(heights.max()) + 0.5 * hull.voxel_size
    top = top_height + offset  # the hull's top, measured from the origin along the normal
    if top <= target_radius:
        return SilhouetteFit(top, 1.0, np.zeros(3))
    # The origin's foot on the plane, raised to half the hull's height.
    shift = normal * (offset + top_height / 2.0)
    radius = max(float(np.percentile(np.linalg.norm(centers - shift, axis=1), config.radius_percentile)),
                 top_height / 2.0)
    return SilhouetteFit(top, fill * target_radius / radius, shift)


# The first, wide carve of size_world_from_silhouettes reaches this share of the way to the nearest
# camera: whatever the cameras' guess of the object's size, the object is in front of every camera.
WIDE_REACH = 0.9


def size_world_from_silhouettes(
    masks: dict[str, np.ndarray],
    cameras: dict[str, Camera],
    target_radius: float,
    fill: float,
    search_radius: float,
    config: SilhouetteFitConfig = SilhouetteFitConfig(),
    trusted_masks: bool = False,
) -> SilhouetteFit | None:
    """The similarity that makes the masks' hull fill the ball of `target_radius` to `fill`, for a
    world sized from the cameras alone (see the module docstring); None with fewer than 3 usable masks
    or when the masks agree on nothing. `top` is the hull's farthest reach from the origin before the move.
    A voxel counts only where half the views or more see it: near the cameras, a corner of space few
    views cover is not carved by the rest. `trusted_masks` (from alpha or the user's files): every
    view carves, none is outvoted. The automatic masks' tolerance of a few wrong views would let the
    three low views of the NeRF lego, the only ones that see under its base plate, be outvoted, and
    the hull then reached twice the object's height below it."""
    usable = {f: m for f, m in masks.items() if f in cameras and check_mask(m) is None}
    if len(usable) < 3:
        return None
    views = {f: cameras[f] for f in usable}
    nearest = min(float(np.linalg.norm(c.center)) for c in views.values())
    scale, shift, top = 1.0, np.zeros(3), None
    for reach in (WIDE_REACH * nearest, search_radius):
        # Each pass carves in the frame the previous one made: its cameras moved, its masks unchanged.
        moved = {f: moved_camera(c, scale, shift) for f, c in views.items()}
        hull = carve_visual_hull(usable, moved, radius=reach, resolution=config.resolution,
                                 min_views_fraction=1.0 if trusted_masks else config.min_views_fraction,
                                 within_sphere=True, min_views=max(3, (len(usable) + 1) // 2))
        _drop_specks(hull)
        if hull.is_empty:
            return None
        centers = hull.occupied_centers()
        if top is None:
            top = float(np.linalg.norm(centers, axis=1).max()) + 0.5 * hull.voxel_size
        middle = 0.5 * (centers.min(axis=0) + centers.max(axis=0))
        farthest = float(np.linalg.norm(centers - middle, axis=1).max()) + VOXEL_HALF_DIAGONAL * hull.voxel_size
        step = fill * target_radius / farthest
        # x -> step * (scale * (x - shift) - middle) = scale * step * (x - (shift + middle / scale))
        shift, scale = shift + middle / scale, scale * step
    return SilhouetteFit(top, scale, shift)


def _drop_specks(hull, min_fraction: float = 0.05) -> None:
    """Drop the hull's pieces under `min_fraction` of its largest: stray voxels that half the views
    see and none carves (where few views overlap) would otherwise set the farthest reach. On the lego
    on white (30 views, the backdrop's outlines), scattered voxels reached 0.7 from the origin where
    the object ended at 0.05, and the world was sized to them (the object 0.67 across instead of 1.7)."""
    from scipy import ndimage

    labels, n = ndimage.label(hull.occupancy, structure=np.ones((3, 3, 3), bool))
    if n <= 1:
        return
    sizes = np.bincount(labels.ravel())[1:]
    keep = np.concatenate([[False], sizes >= min_fraction * sizes.max()])
    hull.occupancy &= keep[labels]


def moved_camera(camera: Camera, scale: float, shift: np.ndarray) -> Camera:
    """The camera in the world moved by x -> scale * (x - shift) (orientation unchanged)."""
    return camera.moved_by(_similarity(scale, shift))


def _similarity(scale: float, shift: np.ndarray) -> np.ndarray:
    """x -> scale * (x - shift) as a 4x4."""
    step = np.eye(4)
    step[:3, :3] *= scale
    step[:3, 3] = -scale * np.asarray(shift, dtype=np.float64)
    return step


def moved_normalization(norm: Normalization, scale: float, shift: np.ndarray) -> Normalization:
    """`norm` followed by x -> scale * (x - shift): the transform, the plane and its margin."""
    world_from_source = _similarity(scale, shift) @ norm.world_from_source
    source_from_world = np.linalg.inv(world_from_source)
    plane = None
    if norm.plane is not None:
        normal = np.asarray(norm.plane[0], dtype=np.float64)
        plane = (normal, float(scale * (norm.plane[1] - normal @ shift)))
    return Normalization(
        world_from_source,
        center_source=source_from_world[:3, 3].copy(),
        radius_source=norm.radius_source / scale,  # fill * R over the new, larger total scale
        up_source=norm.up_source,
        used_points=norm.used_points,
        plane=plane,
        plane_margin=norm.plane_margin * scale,
    )
