"""Automatic object masks for photos with real backgrounds.

Per view, GrabCut (colour models + graph cut) separates the object from its background, seeded by
what posing already knows:

- the object lies inside the ball of `radius` around the origin (the normalised world), so pixels
  outside that ball's projection are background for sure;
- sparse SfM points inside the ball mostly lie on the object: the convex hull of their projection,
  dilated, near the points, is "probably object" and the points near the centre are "object";
- sparse points outside the ball are background structure: where they project in front of the
  ball they are "background" seeds; the image border is "probably background".

Without points (imported poses), a smaller ball around the origin stands for the object.

Above a floor, pixels whose colour disagrees with what nearby views see at the floor point behind
them are definite object (floor_parallax.py): parallax, evidence that colour models lack where the
object is coloured like the floor (a cream neck on pale gravel).

On a plain backdrop (plain_backdrop.py: a studio sweep, a lightbox), the backdrop joined to the
photo's border is definite background and what is not the backdrop's colour inside the ball is
probably object, whatever the points say; the points' convex hull does not trim the visual hull
there (each view outlines the object by itself).

This first pass runs small (a rough mask is all it must give). Then the views are made to agree:
a visual hull carved from all first-pass masks (and, with points, cut to the points' convex hull)
is projected back into each view, and a second GrabCut at the working size starts from the mask
trimmed to the hull's outline, with what the hull has and the mask missed as "probably object"
and a band around it as "probably background". This removes background that only some views
took for object (what every view took for object, e.g. background seen through a gap of the
object, the hull cannot know about) and refines the outline. GrabCut works on a crop around the
ball; masks are brought back to full size with an edge-aware (guided) filter so outlines follow
the photo's edges rather than the reduced pixels.

Measured on the NeRF lego composited onto the fox photos (tests/engine/capture/test_auto_mask.py):
mean IoU 0.94 with points, 0.87 without; about 0.7 s per 800-960 px view on one CPU core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import cv2
import numpy as np

from lirm.engine.cameras import Camera, nearest_cameras
from lirm.engine.capture.floor_parallax import floor_agreement, floor_disagreement, floor_sight, off_floor_evidence
from lirm.engine.capture.masks import check_mask
from lirm.engine.capture.normalize import is_floor
from lirm.engine.capture.plain_backdrop import BACKDROP, BACKDROP_COLOURED
from lirm.engine.capture.visual_hull import (
    VoxelHull,
    carve_visual_hull,
    cut_below_plane,
    cut_outside_points,
    project_hull,
    project_points,
    sphere_silhouette,
)

__all__ = ["AutoMaskConfig", "automatic_masks", "clean_mask"]

_BGD, _FGD, _PR_BGD, _PR_FGD = cv2.GC_BGD, cv2.GC_FGD, cv2.GC_PR_BGD, cv2.GC_PR_FGD


@dataclass
class AutoMaskConfig:
    """Knobs of `automatic_masks`. Lengths given as fractions are of the crop's long side, so they
    mean the same at any photo size."""

    # Two GrabCut sizes: the crop around the object's ball is resized to this long side for the
    # seeded first pass (a rough mask; weak seeds make graph cuts slow, so small) and for the
    # refining second pass (a narrow uncertain band around the outline, so it can be bigger).
    seed_long_side: int = 240
    work_long_side: int = 480
    # GrabCut iterations (colour-model re-estimation + graph cut) of the seeded pass and of each
    # refining pass.
    seed_iterations: int = 3
    refine_iterations: int = 1
    # Long side of the small copy on which GrabCut's colour mixtures are first fitted.
    model_long_side: int = 160
    # Margin around the ball's projection before "definitely background" starts (fraction).
    sphere_margin: float = 0.02
    # The convex hull of the projected object points is dilated by this much to become "probably
    # object": sparse points stop short of the outline (fraction).
    seed_hull_dilation: float = 0.04
    # Of that region, only pixels within this distance of a projected point start as "probably
    # object" (fraction; 0 uses the whole dilated hull).
    seed_reach: float = 0.05
    # Radius in seed-pass pixels of the discs drawn at projected points as definite object /
    # background seeds; 0 disables definite seeds (the points then only shape the region).
    seed_radius_px: int = 1
    # Object points nearer than this fraction of `radius` to the origin become definite object
    # seeds; those further out (more likely the ground the object stands on) only shape the region.
    fg_seed_core: float = 0.8
    # With points: the projection of a ball of this fraction of `radius` also starts as "probably
    # object", so object parts without sparse points (a smooth handle) can win on colour; 0 keeps
    # the points' region alone. Use it when normalisation sized the object reliably (the pipeline
    # sets it when a support plane was found).
    ball_probable_fraction: float = 0.0
    # Fewer object points than this in a view: seed it as in the no-points mode.
    min_fg_points: int = 8
    # No-points mode: the projection of a ball of this fraction of `radius` is "probably object".
    no_points_fg_fraction: float = 0.8
    # Width of the image-border strip that is "probably background" (fraction).
    border: float = 0.01
    # Clean-up: components smaller than this fraction of the largest are dropped, holes smaller
    # than this fraction of the object's area are filled (bigger holes are real, e.g. a handle).
    min_component_fraction: float = 0.02
    max_hole_fraction: float = 0.01
    # Multi-view consistency: carve a visual hull from the masks and refine every view inside its
    # outline, this many times; 0 refines each view alone (also when there are fewer than 3 views).
    consistency_passes: int = 1
    hull_resolution: int = 80
    # Fraction of the views that see a voxel that must agree it is object; below 1 so that one bad
    # first-pass mask does not cut a hole into the hull.
    hull_min_views_fraction: float = 0.85
    # With points: the hull is also cut to the convex hull of the points inside the ball, grown by
    # this fraction of `radius` (sparse points stop short of the object's outline); negative
    # disables.
    point_hull_margin: float = 0.1
    # Refining pass: pixels inside the hull's outline that the mask missed start as probably object.
    hull_fills: bool = True
    # Refining pass: the uncertain band reaches this far outside the (hull-trimmed) mask; beyond it
    # is definite background (fraction).
    refine_band: float = 0.02
    # Refining pass: the mask eroded by this much is definite object (fraction).
    refine_core_erosion: float = 0.0
    # Above a floor: pixels whose colour disagrees with what nearby views see at the floor point
    # their ray meets (floor_parallax.py) by more than this (0-255) are definite object in both
    # passes; 0 turns it off. Against colour models that take a dark cap or a cream neck for the
    # floor (README, "Captures").
    floor_parallax_threshold: float = 48.0
    floor_parallax_neighbours: int = 4
    # Above a textured floor: pixels whose pattern matches what two nearby views see round the same
    # floor point (floor_parallax.floor_agreement, zero-mean correlation above this) are definite
    # background in the refining pass: the floor seen through a mug's handle, which the first pass
    # and the hull take for object (every view sees the hole filled with object-like colour). Not
    # where the floor point lies within `floor_contact_margin` (fraction of the ball's radius) of
    # where the hull meets the floor: the object's base is within a pixel's parallax of the floor
    # there and agrees with it. 0 turns it off.
    floor_agreement_threshold: float = 0.8
    floor_contact_margin: float = 0.15
    # Edge refinement when upsampling to full size: guided filter radius (full-size pixels, scaled
    # with the upsampling factor) and regularisation (guide intensities in [0, 1]); falls back to
    # bilinear upsampling when opencv-contrib's ximgproc is missing.
    refine_edges: bool = True
    guided_radius_px: int = 2
    guided_eps: float = 1e-3


@dataclass
class _Level:
    """The crop at one GrabCut size: image, the camera of that image, inside of the grown ball."""

    image: np.ndarray
    camera: Camera
    inside_ball: np.ndarray
    # Pixels that cannot be the floor (floor_parallax.py), or None where that is not known.
    off_floor: np.ndarray | None = None
    # Pixels whose floor pattern matches nearby views' (floor_parallax.floor_agreement): (N, 2)
    # pixel indices (row, column) and the (N, 3) floor points their rays meet; None where unknown.
    on_floor: tuple[np.ndarray, np.ndarray] | None = None
    # On a plain backdrop (plain_backdrop.py): the backdrop map at this level's size, else None.
    backdrop: np.ndarray | None = None


@dataclass
class _View:
    """One view's crop around the object's ball (full-image pixel box) at the two GrabCut sizes."""

    frame: str
    full_w: int
    full_h: int
    x0: int
    y0: int
    x1: int
    y1: int
    seed: _Level
    work: _Level


def _attach_backdrop(view: _View, backdrop: np.ndarray) -> None:
    """The photo's backdrop map cropped and brought to both GrabCut sizes: definite backdrop only
    where every photo pixel under a level's pixel is (an outline pixel mixes object and backdrop)."""
    crop = np.asarray(backdrop)[view.y0:view.y1, view.x0:view.x1]
    for level in (view.seed, view.work):
        size = (level.camera.width, level.camera.height)
        definite = cv2.resize((crop == BACKDROP).astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.999
        coloured = cv2.resize((crop >= BACKDROP_COLOURED).astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5
        level.backdrop = np.where(definite, BACKDROP, np.where(coloured, BACKDROP_COLOURED, 0)).astype(np.uint8)


def _odd_kernel(radius_px: float) -> np.ndarray:
    r = max(int(round(radius_px)), 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def _level(crop: np.ndarray, camera: Camera, x0: int, y0: int, long_side: int, radius: float,
           cfg: AutoMaskConfig) -> _Level:
    ch, cw = crop.shape[:2]
    scale = min(1.0, long_side / max(cw, ch))
    ow, oh = max(int(round(cw * scale)), 1), max(int(round(ch * scale)), 1)
    img = crop if (ow, oh) == (cw, ch) else cv2.resize(crop, (ow, oh), interpolation=cv2.INTER_AREA)
    cam = camera.crop_resize(x0, y0, cw, ch, ow, oh)
    inside = sphere_silhouette(cam, radius)
    inside = cv2.dilate(inside, _odd_kernel(cfg.sphere_margin * max(ow, oh))) > 0
    return _Level(np.ascontiguousarray(img), cam, inside)


def _prepare_view(frame: str, image: np.ndarray, camera: Camera, radius: float, cfg: AutoMaskConfig) -> _View:
    h, w = image.shape[:2]
    if (w, h) != (camera.width, camera.height):
        raise ValueError(f"frame {frame!r}: image is {w}x{h} but its camera is {camera.width}x{camera.height}")
    ys, xs = np.nonzero(sphere_silhouette(camera, radius))
    if len(xs) == 0:
        x0 = y0 = 0
        x1, y1 = w, h
    else:
        margin = int(math.ceil(cfg.sphere_margin * max(w, h))) + 2
        x0, x1 = max(int(xs.min()) - margin, 0), min(int(xs.max()) + 1 + margin, w)
        y0, y1 = max(int(ys.min()) - margin, 0), min(int(ys.max()) + 1 + margin, h)
    crop = image[y0:y1, x0:x1]
    return _View(
        frame, w, h, x0, y0, x1, y1,
        _level(crop, camera, x0, y0, cfg.seed_long_side, radius, cfg),
        _level(crop, camera, x0, y0, cfg.work_long_side, radius, cfg),
    )


# The floor evidence looks this far (times the object's ball) from the plane's point under the
# origin: far enough for rays past a tall object's top to meet the floor behind it.
_FLOOR_REACH = 8.0


def _attach_floor_evidence(views: dict[str, "_View"], images: Mapping[str, np.ndarray], cameras: Mapping[str, Camera],
                           plane: tuple[np.ndarray, float], radius: float, cfg: AutoMaskConfig) -> None:
    """Each view's off-floor pixels (floor_parallax.py) at its working size, and at its seed size.
    Computed on the working crop against the nearest views' photos brought to the same scale (at
    full size it cost 1.5 s a 1280 x 960 view; at the working size about 0.1 s)."""
    scale = float(np.median([v.work.camera.width / (v.x1 - v.x0) for v in views.values()]))
    scaled: dict[str, tuple[Camera, np.ndarray]] = {}
    for f, view in views.items():
        w, h = max(int(round(view.full_w * scale)), 1), max(int(round(view.full_h * scale)), 1)
        image = np.ascontiguousarray(np.asarray(images[f])[:, :, :3])
        if (w, h) != (view.full_w, view.full_h):
            image = cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
        scaled[f] = (cameras[f].crop_resize(0, 0, view.full_w, view.full_h, w, h), image)
    for f, view in views.items():
        work = view.work
        # 1.5 pixels of a 640-pixel photo (poses are right to about a pixel), in working pixels.
        blur = 1.5 * max(view.full_w, view.full_h) / 640.0 * work.camera.width / (view.x1 - view.x0)
        others = [scaled[g] for g in nearest_cameras({g: cameras[g] for g in views}, f, cfg.floor_parallax_neighbours)]
        sight = floor_sight(work.camera, work.image, others, plane, reach=_FLOOR_REACH * radius, blur_px=max(blur, 0.5))
        disagreement = floor_disagreement(work.camera, work.image, others, plane, sight=sight)
        work.off_floor = off_floor_evidence(disagreement, cfg.floor_parallax_threshold)
        if cfg.floor_agreement_threshold > 0:
            agreement = floor_agreement(work.camera, work.image, others, plane, sight=sight)
            pixels = np.argwhere(np.nan_to_num(agreement, nan=-1.0) > cfg.floor_agreement_threshold)
            work.on_floor = (pixels, sight.points[pixels[:, 0], pixels[:, 1]])
        size = (view.seed.camera.width, view.seed.camera.height)
        view.seed.off_floor = cv2.resize(work.off_floor.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5


# Hull voxels this many voxels above the floor (after cut_below_plane's layer) count as its base.
_CONTACT_VOXELS = 4.0


def _away_from_contact(on_floor: tuple[np.ndarray, np.ndarray], hull: VoxelHull | None,
                       plane: tuple[np.ndarray, float] | None, margin: float) -> np.ndarray:
    """The on-floor pixels whose floor point lies farther than `margin` from where the hull meets
    the floor (its voxels within a few of the plane, projected onto it, on a grid of the hull's
    voxels). Without a hull or a plane, none: nothing says where the object's base is."""
    pixels, points = on_floor
    if hull is None or plane is None or len(pixels) == 0:
        return pixels[:0]
    normal, offset = np.asarray(plane[0], dtype=np.float64), float(plane[1])
    centres = hull.occupied_centers()
    base = centres[centres @ normal - offset < (1.5 + _CONTACT_VOXELS) * hull.voxel_size]
    if len(base) == 0:
        return pixels
    # Two axes in the plane; the grid spans the hull's cube (a floor point beyond is far from the base).
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    cells = 2 * int(math.ceil(np.sqrt(3.0) * hull.resolution / 2.0)) + 1
    half = cells // 2

    def cell_of(p: np.ndarray) -> np.ndarray:
        return np.round(np.stack([p @ u, p @ v], axis=-1) / hull.voxel_size).astype(np.int64) + half

    grid = np.zeros((cells, cells), np.uint8)
    ij = cell_of(base)
    grid[ij[:, 0], ij[:, 1]] = 1
    grid = cv2.dilate(grid, _odd_kernel(margin / hull.voxel_size)) > 0
    ij = cell_of(points)
    inside = np.all((ij >= 0) & (ij < cells), axis=1)
    near = np.zeros(len(points), bool)
    near[inside] = grid[ij[inside, 0], ij[inside, 1]]
    return pixels[~near]


@dataclass
class _Seeds:
    """Projected sparse points in one level's pixels."""

    fg: np.ndarray  # points inside the ball: (N, 2)
    core: np.ndarray  # the subset near the centre, definite object seeds
    bg: np.ndarray  # points outside the ball and in front of it: definite background seeds


def _project_seeds(level: _Level, points: np.ndarray, radius: float, cfg: AutoMaskConfig,
                   is_object: np.ndarray | None = None, seen: np.ndarray | None = None) -> _Seeds:
    cam = level.camera
    empty = np.zeros((0, 2))
    if len(points) == 0:
        return _Seeds(empty, empty, empty)
    xy, z, valid = project_points(cam, points)
    on_img = valid & (xy[:, 0] >= 0) & (xy[:, 0] < cam.width) & (xy[:, 1] >= 0) & (xy[:, 1] < cam.height)
    norm = np.linalg.norm(points, axis=1)
    inner = norm <= radius
    # A point outside the ball is only known to be visible background when it is nearer to the
    # camera than the ball; behind the ball the object may hide it.
    ball_near = np.linalg.norm(cam.center) - radius
    background = on_img & ~inner & (z < ball_near)
    if is_object is not None:
        # Points inside the ball that are not the object (the table it stands on) are background
        # where they lie nearer than the object's centre; farther ones may be hidden behind it.
        background |= on_img & inner & ~is_object & (z < np.linalg.norm(cam.center))
        if seen is not None:
            # Observed by this photo, so not hidden in it: background wherever it lies.
            background |= on_img & ~is_object & seen
        inner = inner & is_object
    fg = xy[on_img & inner]
    if len(fg) < cfg.min_fg_points:
        return _Seeds(empty, empty, xy[background])
    return _Seeds(fg, xy[on_img & inner & (norm <= cfg.fg_seed_core * radius)], xy[background])


def _draw_seeds(tri: np.ndarray, seeds: _Seeds, level: _Level, cfg: AutoMaskConfig) -> None:
    if cfg.seed_radius_px <= 0:
        return
    # Seed discs keep their size in the photo whatever the level's resolution.
    r = cfg.seed_radius_px * max(level.camera.width, level.camera.height) / cfg.seed_long_side
    for xy, label in ((seeds.bg, _BGD), (seeds.core, _FGD)):
        if len(xy):
            dots = np.zeros(tri.shape, np.uint8)
            ij = np.floor(xy).astype(np.int64)
            dots[ij[:, 1], ij[:, 0]] = 1
            dots = cv2.dilate(dots, _odd_kernel(r)) > 0
            tri[dots & level.inside_ball] = label


def _seed_trimap(view: _View, seeds: _Seeds, radius: float, cfg: AutoMaskConfig) -> np.ndarray:
    """First-pass GrabCut labels from the ball, the sparse points and the image border."""
    lvl = view.seed
    cam = lvl.camera
    h, w = cam.height, cam.width
    long_side = max(w, h)
    tri = np.full((h, w), _BGD, np.uint8)
    tri[lvl.inside_ball] = _PR_BGD
    if len(seeds.fg):
        region = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(region, cv2.convexHull(np.floor(seeds.fg).astype(np.int32)), 1)
        region = cv2.dilate(region, _odd_kernel(cfg.seed_hull_dilation * long_side)) > 0
        if cfg.seed_reach > 0:
            # Background seen through gaps of the object lies inside the points' convex hull but
            # far from every point; starting it as background keeps the object's colour model clean.
            dots = np.zeros((h, w), np.uint8)
            ij = np.floor(seeds.fg).astype(np.int64)
            dots[ij[:, 1], ij[:, 0]] = 1
            region &= cv2.dilate(dots, _odd_kernel(cfg.seed_reach * long_side)) > 0
        if cfg.ball_probable_fraction > 0:
            region |= sphere_silhouette(cam, cfg.ball_probable_fraction * radius) > 0
    else:
        # No-points mode (or too few points here): a smaller ball stands for the object.
        region = sphere_silhouette(cam, cfg.no_points_fg_fraction * radius) > 0
    tri[region & lvl.inside_ball] = _PR_FGD

    b = max(int(round(cfg.border * long_side)), 1)
    border = np.zeros((h, w), bool)
    # Only the photo's own border: a crop edge inside the photo is already outside the ball.
    if view.x0 == 0:
        border[:, :b] = True
    if view.y0 == 0:
        border[:b] = True
    if view.x1 == view.full_w:
        border[:, -b:] = True
    if view.y1 == view.full_h:
        border[-b:] = True
    tri[border & (tri != _BGD)] = _PR_BGD
    _apply_backdrop(tri, lvl)
    if lvl.off_floor is not None:
        tri[lvl.off_floor & lvl.inside_ball] = _FGD
    _draw_seeds(tri, seeds, lvl, cfg)
    return tri


def _apply_backdrop(tri: np.ndarray, level: _Level) -> None:
    """On a plain backdrop: what is not the backdrop's colour inside the ball is probably object
    (the points miss smooth parts, and the backdrop has nothing else to offer), the backdrop's
    colour away from the border probably background (a gap of the object, or a part coloured like
    the backdrop: the colour models and the hull decide), the backdrop joined to the border
    definitely background."""
    if level.backdrop is None:
        return
    tri[(level.backdrop == 0) & level.inside_ball & (tri != _FGD)] = _PR_FGD
    tri[(level.backdrop == BACKDROP_COLOURED) & (tri == _PR_FGD)] = _PR_BGD
    tri[level.backdrop == BACKDROP] = _BGD


def _grabcut(
    image: np.ndarray, trimap: np.ndarray, iterations: int, cfg: AutoMaskConfig,
    models: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None:
    """(bool object mask, colour models), or None when GrabCut cannot run (no object or no
    background labels, or a colour model without enough distinct samples).

    OpenCV's GrabCut spends most of a first call seeding its colour mixtures with k-means over
    every pixel; seeding them on a small copy and then iterating at full working size with
    GC_EVAL (which re-learns the mixtures from the labels each iteration) gives the same result
    in about half the time. `models` from an earlier call skip the seeding.
    """
    labels = trimap.copy()
    has_fg = np.any((labels == _FGD) | (labels == _PR_FGD))
    has_bg = np.any((labels == _BGD) | (labels == _PR_BGD))
    if not (has_fg and has_bg) or iterations < 1:
        return None
    try:
        if models is None:
            h, w = labels.shape
            scale = min(1.0, cfg.model_long_side / max(h, w))
            size = (max(int(round(w * scale)), 1), max(int(round(h * scale)), 1))
            small = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
            small_labels = cv2.resize(labels, size, interpolation=cv2.INTER_NEAREST)
            if not (np.any(small_labels % 2 == 1) and np.any(small_labels % 2 == 0)):
                small, small_labels = image, labels.copy()
            bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
            cv2.setRNGSeed(0)  # GrabCut seeds its colour mixtures by k-means on OpenCV's global generator
            cv2.grabCut(small, small_labels, None, bgd, fgd, 1, cv2.GC_INIT_WITH_MASK)
        else:
            bgd, fgd = models[0].copy(), models[1].copy()
        cv2.grabCut(image, labels, None, bgd, fgd, iterations, cv2.GC_EVAL)
    except cv2.error:
        return None
    return (labels == _FGD) | (labels == _PR_FGD), (bgd, fgd)


def clean_mask(mask: np.ndarray, min_component_fraction: float = 0.02, max_hole_fraction: float = 0.01) -> np.ndarray:
    """Drop specks and fill pinholes of a bool mask.

    Components smaller than `min_component_fraction` of the largest go; holes (background regions
    not connected to the image border) smaller than `max_hole_fraction` of the object's area are
    filled. Bigger holes are kept: they are usually real (a handle, a gap between parts).
    """
    m = np.asarray(mask, bool)
    if not m.any():
        return m.copy()
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m.astype(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.concatenate([[False], areas >= min_component_fraction * areas.max()])
    m = keep[labels]
    bg = (~m).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(bg, connectivity=4)
    touches = np.zeros(n, bool)
    for edge in (labels[0], labels[-1], labels[:, 0], labels[:, -1]):
        touches[np.unique(edge)] = True
    small = stats[:, cv2.CC_STAT_AREA] < max_hole_fraction * np.count_nonzero(m)
    fill = ~touches & small
    fill[0] = False
    return m | fill[labels]


def _refine_trimap(
    level: _Level, mask: np.ndarray, hull_mask: np.ndarray | None, seeds: _Seeds, cfg: AutoMaskConfig,
    floor_seen: np.ndarray | None = None,
) -> np.ndarray:
    """Refining-pass labels: the mask, trimmed to the hull's outline when there is one, is probably
    object, a band around it probably background, the rest background; the points' seeds (and
    optionally the mask's eroded core) are definite."""
    long_side = max(level.camera.width, level.camera.height)
    m = mask if hull_mask is None else mask & (hull_mask > 0)
    m8 = m.astype(np.uint8)
    band = cv2.dilate(m8, _odd_kernel(cfg.refine_band * long_side)) > 0
    tri = np.full(m.shape, _BGD, np.uint8)
    tri[band & level.inside_ball] = _PR_BGD
    if hull_mask is not None and cfg.hull_fills:
        # What the other views agree is object and this view missed starts as object; GrabCut
        # still decides by colour, which is what keeps the hull's coarse outline out.
        fill = (hull_mask > 0) & ~mask & level.inside_ball
        tri[fill] = _PR_FGD
    tri[m] = _PR_FGD
    if cfg.refine_core_erosion > 0:
        tri[cv2.erode(m8, _odd_kernel(cfg.refine_core_erosion * long_side)) > 0] = _FGD
    if level.backdrop is not None:
        tri[level.backdrop == BACKDROP] = _BGD
    if floor_seen is not None and len(floor_seen):
        # The floor seen through the object (a handle's hole): background, whatever the hull says.
        tri[floor_seen[:, 0], floor_seen[:, 1]] = _BGD
    if level.off_floor is not None:
        tri[level.off_floor & level.inside_ball] = _FGD
    _draw_seeds(tri, seeds, level, cfg)
    return tri


def _trim_to_points(hull: VoxelHull, points: np.ndarray, radius: float, cfg: AutoMaskConfig,
                    is_object: np.ndarray | None = None) -> None:
    """Drop hull voxels outside the convex hull of the object's sparse points, grown by a margin
    (visual_hull.cut_outside_points: views from one side cannot carve the space under the object)."""
    keep = np.linalg.norm(points, axis=1) <= radius
    if is_object is not None:
        keep &= is_object
    inner = points[keep]
    if cfg.point_hull_margin < 0 or len(inner) < max(cfg.min_fg_points, 4) or hull.is_empty:
        return
    cut_outside_points(hull, inner, cfg.point_hull_margin * radius)


def _upsample(view: _View, mask: np.ndarray, image: np.ndarray, cfg: AutoMaskConfig) -> np.ndarray:
    """Full-size uint8 mask from a bool mask of the crop (any size), edges snapped to the photo's
    edges."""
    fh, fw = image.shape[:2]
    cw, ch = view.x1 - view.x0, view.y1 - view.y0
    soft = mask.astype(np.float32)
    if soft.shape != (ch, cw):
        soft = cv2.resize(soft, (cw, ch), interpolation=cv2.INTER_LINEAR)
        factor = cw / mask.shape[1]
        if cfg.refine_edges and hasattr(cv2, "ximgproc"):
            guide = image[view.y0:view.y1, view.x0:view.x1].astype(np.float32) / 255.0
            r = max(int(round(cfg.guided_radius_px * factor)), 1)
            soft = cv2.ximgproc.guidedFilter(guide, soft, r, cfg.guided_eps)
    out = np.zeros((fh, fw), np.uint8)
    out[view.y0:view.y1, view.x0:view.x1] = np.where(soft > 0.5, 255, 0).astype(np.uint8)
    return out


def automatic_masks(
    images: Mapping[str, np.ndarray],
    cameras: Mapping[str, Camera],
    points: np.ndarray | None = None,
    radius: float = 1.0,
    config: AutoMaskConfig = AutoMaskConfig(),
    progress: Callable[[int, int], None] | None = None,
    point_is_object: np.ndarray | None = None,
    support_plane: tuple[np.ndarray, float] | None = None,
    observations: Mapping[str, np.ndarray] | None = None,
    backdrops: Mapping[str, np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """Object masks (uint8, 255 = object, full image size) for every frame in both dicts.

    images: frame id -> RGB uint8 photo at its camera's size. points: (N, 3) sparse SfM points in
    the normalised world, or None / empty for the no-points mode. point_is_object: optional (N,)
    booleans from normalisation (False for the support plane's points); without it every point
    inside the ball counts as object. support_plane: optional (unit normal, offset) of the surface
    the object stands on (n . x = offset, normal toward the cameras); the hull is cut there instead
    of at the points' convex hull, which would also cut object parts that carry few points (a
    smooth handle). observations: optional frame id -> indices of the points that photo observed
    (SfM tracks); an observed point that is not the object is visible background in that photo,
    wherever it lies (a wall behind a wall-mounted object). backdrops: optional frame id -> backdrop
    map (plain_backdrop.py) of photos shot on a plain backdrop. radius: the object lies inside
    this ball around the origin. progress(done, total) is called after each step of each view;
    raise from it to cancel. See the module docstring for the method and AutoMaskConfig for knobs.
    """
    cfg = config
    pts = np.zeros((0, 3)) if points is None else np.asarray(points, dtype=np.float64).reshape(-1, 3)
    labels = None if point_is_object is None else np.asarray(point_is_object, dtype=bool).reshape(-1)
    finite = np.all(np.isfinite(pts), axis=1)
    pts = pts[finite]
    if labels is not None:
        labels = labels[finite]
    frames = [f for f in images if f in cameras]
    use_hull = cfg.consistency_passes > 0 and len(frames) >= 3
    refinements = max(cfg.consistency_passes, 1) if use_hull else 1
    total, done = len(frames) * (1 + refinements), 0

    def tick() -> None:
        nonlocal done
        done += 1
        if progress is not None:
            progress(done, total)

    seen_by: dict[str, np.ndarray] = {}
    if observations is not None and labels is not None:
        for f in frames:
            if f in observations:
                seen = np.zeros(len(finite), bool)
                seen[np.asarray(observations[f], dtype=np.int64)] = True
                seen_by[f] = seen[finite]
    views: dict[str, _View] = {}
    masks: dict[str, np.ndarray] = {}  # at the seed size until the first refinement, then work size
    floor_known = cfg.floor_parallax_threshold > 0 and is_floor(support_plane) and len(frames) >= 2
    models: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for f in frames:
        img = np.asarray(images[f])
        if img.ndim != 3 or img.shape[2] < 3 or img.dtype != np.uint8:
            raise ValueError(f"frame {f!r}: expected an RGB uint8 image, got {img.dtype} {img.shape}")
        views[f] = _prepare_view(f, np.ascontiguousarray(img[:, :, :3]), cameras[f], radius, cfg)
    for f, backdrop in (backdrops or {}).items():
        if f in views:
            _attach_backdrop(views[f], backdrop)
    if floor_known:
        _attach_floor_evidence(views, images, cameras, support_plane, radius, cfg)
    for f in frames:
        view = views[f]
        seeds = _project_seeds(view.seed, pts, radius, cfg, labels, seen_by.get(f))
        res = _grabcut(view.seed.image, _seed_trimap(view, seeds, radius, cfg), cfg.seed_iterations, cfg)
        if res is None:
            masks[f] = np.zeros(view.seed.image.shape[:2], bool)
        else:
            masks[f] = clean_mask(res[0], cfg.min_component_fraction, cfg.max_hole_fraction)
            models[f] = res[1]
        tick()

    for _ in range(refinements):
        # Carve from the masks at the size they are (seed size on the first round).
        levels = {f: views[f].seed if masks[f].shape == views[f].seed.inside_ball.shape else views[f].work
                  for f in frames}
        hull = None
        if use_hull:
            # Views whose mask is implausible (empty, the whole crop) would only damage the hull.
            usable = {f: np.where(m, 255, 0).astype(np.uint8) for f, m in masks.items()}
            usable = {f: m for f, m in usable.items() if check_mask(m) is None}
            if len(usable) >= 3:
                hull = carve_visual_hull(
                    usable, {f: levels[f].camera for f in usable}, radius=radius,
                    resolution=cfg.hull_resolution, min_views_fraction=cfg.hull_min_views_fraction,
                    within_sphere=True,
                )
                if support_plane is not None:
                    cut_below_plane(hull, support_plane)
                elif not backdrops:
                    # (On a plain backdrop every view outlines the object by itself; the points'
                    # hull would cut what carries few of them, the lego's bucket.)
                    _trim_to_points(hull, pts, radius, cfg, labels)
                if hull.is_empty:
                    hull = None
        for f in frames:
            work = views[f].work
            m = masks[f]
            if m.shape != work.inside_ball.shape:
                m = cv2.resize(m.astype(np.uint8), (work.camera.width, work.camera.height),
                               interpolation=cv2.INTER_LINEAR) > 0
            hull_mask = None if hull is None else project_hull(hull, work.camera)
            floor_seen = None
            if work.on_floor is not None:
                # Only where the trimap would say object matters (the floor beside it is background anyway).
                pixels, points = work.on_floor
                claimed = m if hull_mask is None else m | (hull_mask > 0)
                inside = claimed[pixels[:, 0], pixels[:, 1]]
                floor_seen = _away_from_contact((pixels[inside], points[inside]), hull, support_plane,
                                                cfg.floor_contact_margin * radius)
            tri = _refine_trimap(work, m, hull_mask, _project_seeds(work, pts, radius, cfg, labels, seen_by.get(f)), cfg,
                                 floor_seen)
            res = _grabcut(work.image, tri, cfg.refine_iterations, cfg, models.get(f))
            if res is not None:
                m = clean_mask(res[0], cfg.min_component_fraction, cfg.max_hole_fraction)
                models[f] = res[1]
            masks[f] = m
            tick()

    return {f: _upsample(views[f], masks[f], np.asarray(images[f]), cfg) for f in frames}
