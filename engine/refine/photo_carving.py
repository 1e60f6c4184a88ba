"""The masks' hull carved where the photos see through it: a mug's opening, a bowl's hollow.

A visual hull cannot hold a concavity that every silhouette covers: the masks cap a mug's opening
with a lid at its rim, and the refinement, starting from that lid and sampling only near the hull,
painted the inside onto it (the demo mug's lumpy white-blue lid, README "Lighting and materials").
Yet a photo that looks into the opening sees the inside, and its neighbours see the same inner
point where its true depth puts it, not where the lid does. So, per pixel of each view: sweep the
depth along its ray from where it enters the hull to where it leaves, and correlate the patch round
the pixel with what the neighbours see at each depth (zero-mean normalised cross-correlation of a
small luminance patch, on the camera's fronto-parallel planes). Where the best depth lies
clearly below the hull's surface, and matches clearly better than the surface itself does, the
hull between is empty space; a voxel goes when rays of at least two views say so and no view's
match lies in it.

It only ever removes, and only on evidence: plain patches (a white inside without speckles)
correlate with anything and count for nothing, a match must hold in two neighbours whose
baselines differ (a repeating print lines up in one), and a depth within `min_depth_voxels` of the
hull's surface is the surface (masks and poses are right to about a voxel). Where the hull is
tight (the sides of a convex object) the best depth is the surface, and nothing changes. The same
test carves a hull that is fat where no silhouette shows it (the crook between a handle and its
body) down toward the true surface.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from lirm.engine.cameras import Camera, nearest_cameras

__all__ = ["PhotoCarvingConfig", "PhotoCarving", "photo_carve_occupancy"]


@dataclass(frozen=True)
class PhotoCarvingConfig:
    neighbours: int = 4  # views (nearest by camera centre) each view's patches are matched in
    views_agreeing: int = 2  # a depth's score is its match in the second-best of them
    window_px: int = 3  # the patch: (2 w + 1) pixels square
    blur_px: float = 0.7  # both images blurred first (poses are right to about a pixel)
    min_texture: float = 0.02  # the patch's luminance spread (0-1) below which it says nothing
    min_match: float = 0.7  # the best depth's correlation at least this
    max_difference: float = 0.08  # and the pixel's own luminance (0-1) that close to what the neighbour sees there
    beats_surface_by: float = 0.2  # and this much above the best within a voxel of the hull's surface
    distinct_by: float = 0.1  # and this much above the best two voxels or more from it (a clear peak)
    min_depth_voxels: float = 2.0  # the best depth this far below the hull's surface, at least
    margin_voxels: float = 1.0  # the free space ends this far above the matched point
    step_voxels: float = 0.5  # the sweep's depth step
    core_fraction: float = 0.5  # a free point empties a voxel only within this share of its side round the centre
    min_views: int = 2  # views whose rays must find a voxel empty before it goes


@dataclass
class PhotoCarving:
    """What the carving did, for the refinement's notes and the README."""

    occupancy: np.ndarray  # (R, R, R) bool, the hull carved
    carved_voxels: int
    hull_voxels: int
    pixels_seeing_through: int  # rays (all views) whose best match lay below the hull's surface
    seconds: float = 0.0
    # (R, R, R) bool: voxels holding a point some view matched (the surface the photos saw: an inner
    # wall seen through the opening, or the hull's own surface confirmed); None when not recorded
    seen_surface: np.ndarray | None = None

    def sentence(self) -> str:
        share = self.carved_voxels / max(self.hull_voxels, 1)
        return (f"the photos see through the masks' hull at {self.pixels_seeing_through} pixels: "
                f"{self.carved_voxels} of its {self.hull_voxels} voxels carved ({100 * share:.1f}%)")


def photo_carve_occupancy(occupancy: np.ndarray, radius: float, cameras: list[Camera], images: np.ndarray,
                          masks: np.ndarray, config: PhotoCarvingConfig = PhotoCarvingConfig()) -> PhotoCarving:
    """The hull `occupancy` ((R, R, R) bool over [-radius, radius]^3) with the voxels carved that the
    photos see through. `images`: (V, H, W, 3) sRGB in [0, 1] (the object on any fill); `masks`:
    (V, H, W) in [0, 1]; `cameras`: each view's."""
    start = time.perf_counter()
    occupancy = np.asarray(occupancy, bool)
    resolution = occupancy.shape[0]
    voxel = 2.0 * radius / resolution
    luminance = [_luminance(image, config.blur_px) for image in images]
    free_views = np.zeros(occupancy.shape, np.int16)
    surface_views = np.zeros(occupancy.shape, np.int16)
    seeing_through = 0
    by_index = dict(enumerate(cameras))
    for i, camera in enumerate(cameras):
        others = nearest_cameras(by_index, i, config.neighbours)
        if len(others) < config.views_agreeing:
            break
        through = _view_free_space(i, camera, luminance, masks, cameras, others, occupancy, radius, voxel, config)
        if through is None:
            continue
        free, matched, count = through
        free_views += free
        surface_views += matched
        seeing_through += count
    carve = occupancy & (free_views >= config.min_views) & (free_views > surface_views)
    # Only what opens to the outside: a photo sees a voxel through empty space, so a carved voxel
    # walled in by kept ones is a false match's (a bubble in a solid).
    open_space, _ = ndimage.label(~occupancy | carve)
    outside = np.unique(np.concatenate([open_space[0].ravel(), open_space[-1].ravel(), open_space[:, 0].ravel(),
                                        open_space[:, -1].ravel(), open_space[:, :, 0].ravel(), open_space[:, :, -1].ravel()]))
    carve &= np.isin(open_space, outside[outside > 0])
    carved = occupancy & ~carve
    # Scraps the carving cut loose (a few voxels of a lid whose votes fell short) go with it: small
    # parts the carved space touches, a hundredth of the hull or less.
    parts, count = ndimage.label(carved, structure=np.ones((3, 3, 3)))
    if count > 1:
        sizes = np.bincount(parts.ravel())
        touched = np.unique(parts[ndimage.binary_dilation(carve) & carved])
        scraps = [p for p in touched if p > 0 and sizes[p] <= 0.01 * occupancy.sum()]
        loose = np.isin(parts, scraps)
        carve |= loose
        carved &= ~loose
    return PhotoCarving(carved, int(carve.sum()), int(occupancy.sum()), seeing_through, time.perf_counter() - start,
                        carved & (surface_views > 0))


def _luminance(image: np.ndarray, blur_px: float) -> np.ndarray:
    grey = np.asarray(image[..., :3], np.float32) @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    return cv2.GaussianBlur(grey, (0, 0), blur_px) if blur_px > 0 else grey


def _hull_span(occupancy: np.ndarray, radius: float, origins: np.ndarray, directions: np.ndarray,
               step: float) -> tuple[np.ndarray, np.ndarray]:
    """Per ray, the distances at which it first and last meets an occupied voxel (NaN: never), found by
    stepping `step` through the cube's bounding ball."""
    reach = radius * np.sqrt(3.0)
    b = np.sum(origins * directions, axis=1)
    c = np.sum(origins * origins, axis=1) - reach**2
    disc = np.sqrt(np.maximum(b * b - c, 0.0))
    near = np.maximum(-b - disc, 0.0)
    samples = np.arange(int(np.ceil(2 * reach / step)) + 1) * step
    resolution = occupancy.shape[0]
    t_in = np.full(len(origins), np.nan)
    t_out = np.full(len(origins), np.nan)
    for chunk in range(0, len(origins), 4096):
        part = slice(chunk, chunk + 4096)
        t = near[part, None] + samples[None]
        points = origins[part, None] + t[..., None] * directions[part, None]
        index = np.floor((points + radius) / (2 * radius) * resolution).astype(np.int64)
        inside = np.all((index >= 0) & (index < resolution), axis=-1)
        index = np.clip(index, 0, resolution - 1)
        hit = inside & occupancy[index[..., 0], index[..., 1], index[..., 2]]
        any_hit = hit.any(axis=1)
        first = np.argmax(hit, axis=1)
        last = hit.shape[1] - 1 - np.argmax(hit[:, ::-1], axis=1)
        rows = np.arange(len(t))
        t_in[part] = np.where(any_hit, t[rows, first], np.nan)
        t_out[part] = np.where(any_hit, t[rows, last], np.nan)
    return t_in, t_out


def _plane_warp(camera: Camera, other: Camera, depth: float) -> np.ndarray | None:
    """The homography taking this view's pixel indices to `other`'s (OpenCV's pixel-centre convention)
    for the points at camera depth `depth`; None when a lens distortion makes it no homography."""
    if camera.distortion is not None or other.distortion is not None:
        return None
    corners = np.array([[0.0, 0.0], [camera.width - 1.0, 0.0], [0.0, camera.height - 1.0],
                        [camera.width - 1.0, camera.height - 1.0]])
    origins, directions = camera.rays_at(corners + 0.5)
    along = directions @ camera.forward
    xy, _ = other.project(origins + (depth / along)[:, None] * directions)
    return cv2.getPerspectiveTransform(corners.astype(np.float32), (xy - 0.5).astype(np.float32))


def _seen_at_depth(camera: Camera, other: Camera, image: np.ndarray, mask: np.ndarray, depth: float,
                   origins: np.ndarray, directions: np.ndarray, along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """What `other` sees (its luminance, and whether on its mask) at the points of this view's
    fronto-parallel plane at `depth`."""
    height, width = along.shape
    warp = _plane_warp(camera, other, depth)
    if warp is not None:
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        seen = cv2.warpPerspective(image, warp, (width, height), flags=flags, borderMode=cv2.BORDER_CONSTANT,
                                   borderValue=-1.0)
        on = cv2.warpPerspective(mask, warp, (width, height), flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return seen, on > 0.5
    points = origins + (depth / along)[..., None] * directions
    xy, z = other.project(points.reshape(-1, 3))
    xy = np.nan_to_num(xy - 0.5, nan=-1e4, posinf=-1e4, neginf=-1e4).reshape(height, width, 2).astype(np.float32)
    seen = cv2.remap(image, xy[..., 0], xy[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    on = cv2.remap(mask, xy[..., 0], xy[..., 1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    return seen, (on > 0.5) & (z.reshape(height, width) > 0)


def _view_free_space(i: int, camera: Camera, luminance: list[np.ndarray], masks: np.ndarray, cameras: list[Camera],
                     others: list[int], occupancy: np.ndarray, radius: float, voxel: float,
                     config: PhotoCarvingConfig):
    """(free (R, R, R) int16 0/1: voxels this view's rays find empty, matched: voxels holding a matched
    point, pixels seeing through), or None when the view finds nothing. A plane sweep: fronto-parallel
    planes of this camera from the hull's nearest point to its farthest."""
    own = luminance[i]
    height, width = own.shape
    size = (2 * config.window_px + 1,) * 2
    box = lambda a: cv2.blur(a, size, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    inner = cv2.erode((masks[i] > 0.5).astype(np.uint8), np.ones(size, np.uint8)) > 0
    own_mean = box(own)
    own_var = np.maximum(box(own * own) - own_mean * own_mean, 0.0)
    candidates = inner & (own_var > config.min_texture**2)
    if not candidates.any():
        return None
    origins, directions = camera.pixel_rays()
    along = directions @ camera.forward  # camera depth per unit of ray length
    t_in, t_out = np.full((height, width), np.nan), np.full((height, width), np.nan)
    t_in[candidates], t_out[candidates] = _hull_span(occupancy, radius, origins[candidates], directions[candidates],
                                                     config.step_voxels * voxel)
    z_in, z_out = t_in * along, t_out * along
    candidates &= ~np.isnan(z_in)
    if not candidates.any():
        return None
    step = config.step_voxels * voxel
    planes = np.arange(np.nanmin(z_in[candidates]) - voxel, np.nanmax(z_out[candidates]) + step, step)
    others_masks = {j: (masks[j] > 0.5).astype(np.float32) for j in others}
    scores = np.full((len(planes), height, width), -np.inf, np.float32)
    z_in0, z_out0 = np.nan_to_num(z_in, nan=np.inf), np.nan_to_num(z_out, nan=-np.inf)
    for p, depth in enumerate(planes):
        per_neighbour = []
        for j in others:
            seen, valid = _seen_at_depth(camera, cameras[j], luminance[j], others_masks[j], float(depth),
                                         origins, directions, along)
            whole = box(valid.astype(np.float32)) > 0.999
            seen = np.where(valid, seen, 0.0).astype(np.float32)
            seen_mean = box(seen)
            seen_var = np.maximum(box(seen * seen) - seen_mean * seen_mean, 0.0)
            covariance = box(own * seen) - own_mean * seen_mean
            ncc = covariance / np.sqrt(np.maximum(own_var * seen_var, 1e-8))
            # The pixel itself must look alike too: a window straddling a thin rim and the inside
            # beyond it matches at the inside's depth, though the rim's own pixel does not.
            alike = np.abs(seen - own) < config.max_difference
            per_neighbour.append(np.where(whole & alike & (seen_var > (0.5 * config.min_texture) ** 2), ncc, -1.0))
        nth = config.views_agreeing - 1
        scores[p] = -np.partition(-np.stack(per_neighbour), nth, axis=0)[nth]
        scores[p][depth > z_out0 + step] = -np.inf  # past where the ray leaves the hull
    offset = (planes[:, None, None] - z_in0[None]) / voxel  # voxels under the hull's surface (along the camera's axis)
    at_surface = np.where(np.abs(offset) <= 1.0, scores, -np.inf).max(axis=0)  # best within a voxel of it
    deep = np.where(offset >= config.min_depth_voxels, scores, -np.inf)
    best_plane = deep.argmax(axis=0)
    below = np.take_along_axis(deep, best_plane[None], axis=0)[0]
    below_depth = planes[best_plane]
    # A clear peak: a depth two voxels or more from the best that matches almost as well makes it a guess.
    apart = np.abs(np.arange(len(planes))[:, None, None] - best_plane[None]) * config.step_voxels >= 2.0
    runner_up = np.where(apart, scores, -np.inf).max(axis=0)
    through = (candidates & (below >= config.min_match) & (below >= at_surface + config.beats_surface_by)
               & (below >= runner_up + config.distinct_by))
    # Where the hull's own surface matches best, the photos confirm it: votes against carving there.
    confirmed = candidates & (at_surface >= config.min_match) & (at_surface >= below)
    if not through.any() and not confirmed.any():
        return None
    ys, xs = np.nonzero(through)
    o, d = origins[ys, xs], directions[ys, xs]
    start, length = t_in[ys, xs], (below_depth[ys, xs] / along[ys, xs]) - t_in[ys, xs]
    free = np.zeros(occupancy.shape, bool)
    matched = np.zeros(occupancy.shape, bool)
    resolution = occupancy.shape[0]

    def voxel_of(points: np.ndarray) -> tuple[np.ndarray, ...]:
        index = np.clip(np.floor((points + radius) / (2 * radius) * resolution).astype(np.int64), 0, resolution - 1)
        return index[..., 0], index[..., 1], index[..., 2]

    matched[voxel_of(o + (start + length)[:, None] * d)] = True
    cy, cx = np.nonzero(confirmed)
    inside_surface = t_in[cy, cx, None] + 0.25 * voxel  # within the voxel it enters
    matched[voxel_of(origins[cy, cx] + inside_surface * directions[cy, cx])] = True
    free_length = length - config.margin_voxels * voxel
    fine = 0.125 * voxel  # fine enough that a ray through a voxel's core leaves a point in it
    for s in np.arange(0.0, float(free_length.max(initial=0.0)) + fine, fine):
        keep = free_length >= s
        if not keep.any():
            break
        points = o[keep] + (start[keep] + s)[:, None] * d[keep]
        # Only points near a voxel's centre empty it: a ray grazing a surface passes the corners of
        # voxels whose centres lie inside the object.
        cell = (points + radius) / (2 * radius) * resolution
        core = np.all(np.abs(cell - np.floor(cell) - 0.5) <= config.core_fraction / 2, axis=1)
        free[voxel_of(points[core])] = True
    return free.astype(np.int16), matched.astype(np.int16), int(through.sum())
