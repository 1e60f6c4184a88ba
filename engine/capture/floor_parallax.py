"""Where a photo cannot be showing the floor: the parallax of things standing on it.

Posing knows the floor the object stands on (normalize.py's support plane) and every camera. A pixel
whose ray meets the floor shows that floor point, unless something stands in front of it; another
photo sees the same floor point elsewhere, found by intersecting the ray with the plane and
projecting the point into it. Where the pixel really shows the floor, the two agree (a diffuse
floor looks the same from nearby views, shadows included, since they lie on it); where it shows
the object, they disagree, by more the higher the object's point stands above the floor. This is
evidence that colour alone does not have: the WaterBottle's dark cap and the vase's cream neck
against a pale gravel floor look like background to a colour model, but nothing of the floor is
where they are.

The disagreement of a pixel is its smallest difference over a few nearby views (the smallest, so
that a floor point hidden by the object in one neighbour is seen by another), after both images are
blurred by a pixel or two (poses are right to about a pixel) and the neighbour's colours are scaled
to the photo's on the floor (exposure changes between shots). The automatic masks compute it on
each view's working crop against the neighbours' photos brought to the same scale. Measured on synthetic shoots (16
views, 640 x 480, JPEG): true floor pixels near the object, 99th percentile 14-20 and 99.9th 24-38 of
255; true object pixels, median 24-34. So a high threshold marks a good part of the object and
almost none of the floor; the lowest band of the object, whose parallax is small, is never marked
(the evidence only adds object, it never takes any away).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import cv2
import numpy as np

from lirm.engine.cameras import Camera

__all__ = ["FloorSight", "floor_agreement", "floor_disagreement", "floor_sight", "off_floor_evidence"]


def floor_disagreement(camera: Camera, image: np.ndarray, others: Sequence[tuple[Camera, np.ndarray]],
                       plane: tuple[np.ndarray, float], reach: float = 8.0, blur_px: float = 1.5,
                       sight: "FloorSight | None" = None) -> np.ndarray:
    """(H, W) float32: per pixel of `image` (seen by `camera`), how far its colour (0-255) is from what
    the `others` (camera, image) see at the floor point its ray meets: the smallest difference over
    them. NaN where the ray does not meet the floor within `reach` of the plane's point under the
    origin, or no other view sees that point. Both images are blurred by `blur_px` (this image's
    pixels; the others should be at about the same scale). `sight`: floor_sight's result for the
    same arguments, when the caller also wants the agreement."""
    own, meets, _, seen_by_others = sight or floor_sight(camera, image, others, plane, reach, blur_px)
    best = np.full(meets.shape, np.inf, np.float32)
    for seen, valid in seen_by_others:
        difference = np.abs(own - seen).max(axis=-1)
        best = np.where(valid, np.minimum(best, difference), best)
    best[~meets | np.isinf(best)] = np.nan
    return best


def floor_agreement(camera: Camera, image: np.ndarray, others: Sequence[tuple[Camera, np.ndarray]],
                    plane: tuple[np.ndarray, float], reach: float = 8.0, blur_px: float = 1.5,
                    window_px: int = 3, min_texture: float = 6.0, max_difference: float = 12.0,
                    views_agreeing: int = 2, distinct_by: float = 0.2, shift_px: int = 6,
                    sight: "FloorSight | None" = None) -> np.ndarray:
    """(H, W) float32: per pixel of `image`, how well the floor's pattern round it matches what the
    `others` see round the same floor point: the zero-mean normalised cross-correlation on a
    (2 `window_px` + 1)-pixel square, of the `views_agreeing`-th best of the others whose colour at
    the pixel is also within `max_difference` (0-255) of this one's.

    The converse of the disagreement: a pixel that shows the floor (through a mug's handle, between
    a chair's legs) shows the same pattern as the others at the same floor point, and one that
    shows the object does not, except by chance: a plain patch correlates with any other (patches
    whose own spread is under `min_texture` get NaN, no evidence either way), a repeating print can
    line up with itself in one view (hence two views agreeing, whose baselines differ), a pattern
    that does not change along the parallax (a label's horizontal bands, for cameras round the
    object) matches wherever it is seen (hence a match counts only where it beats, by
    `distinct_by`, the same patch moved by `shift_px` in any of the four directions: the floor's
    pattern matches at its floor point and not beside it), and the object's base stands within a
    pixel's parallax of the floor (the caller keeps away from where the object meets the floor).
    NaN also where the floor is not met or too few others see it."""
    own, meets, _, seen_by_others = sight or floor_sight(camera, image, others, plane, reach, blur_px)
    size = (2 * window_px + 1, 2 * window_px + 1)
    box = lambda a: cv2.blur(a, size, borderType=cv2.BORDER_REFLECT)  # noqa: E731
    own_mean = box(own)
    own_var = np.maximum(box(own * own) - own_mean * own_mean, 0.0).sum(axis=-1)
    textured = own_var > 3.0 * min_texture**2  # the spread over the three channels
    scores, seen_count = [], np.zeros(meets.shape, np.int32)

    def correlation(seen: np.ndarray) -> np.ndarray:
        seen_mean = box(seen)
        seen_var = np.maximum(box(seen * seen) - seen_mean * seen_mean, 0.0).sum(axis=-1)
        covariance = (box(own * seen) - own_mean * seen_mean).sum(axis=-1)
        return covariance / np.sqrt(np.maximum(own_var * seen_var, 1e-6))

    for seen, valid in seen_by_others:
        whole = box(valid.astype(np.float32)) > 0.999  # every pixel of the window seen
        seen = np.where(valid[..., None], seen, 0.0).astype(np.float32)
        ncc = correlation(seen)
        beside = np.max([correlation(np.roll(seen, step, axis=axis)) for axis in (0, 1) for step in (-shift_px, shift_px)], axis=0)
        alike = np.abs(own - seen).max(axis=-1) < max_difference
        scores.append(np.where(whole & alike & (ncc > beside + distinct_by), ncc, -1.0).astype(np.float32))
        seen_count += whole
    if len(scores) < views_agreeing:
        return np.full(meets.shape, np.nan, np.float32)
    ranked = -np.sort(-np.stack(scores), axis=0)  # best first
    agreement = ranked[views_agreeing - 1]
    agreement[~meets | ~textured | (seen_count < views_agreeing)] = np.nan
    return agreement


class FloorSight(NamedTuple):
    """One photo's floor as it and the others see it (floor_sight)."""

    own: np.ndarray  # (H, W, 3) float32: the photo, blurred
    meets: np.ndarray  # (H, W) bool: where its rays meet the floor within reach
    points: np.ndarray  # (H, W, 3): where each pixel's ray meets the floor's plane
    seen_by_others: list  # per other view: ((H, W, 3) what it sees at those floor points, (H, W) where it sees them)


def floor_sight(camera: Camera, image: np.ndarray, others: Sequence[tuple[Camera, np.ndarray]],
                plane: tuple[np.ndarray, float], reach: float = 8.0, blur_px: float = 1.5) -> FloorSight:
    """This image blurred, where its rays meet the floor, and per other view what it sees at those
    floor points (blurred, its exposure scaled to this photo's) with where it sees them."""
    normal, offset = np.asarray(plane[0], dtype=np.float64), float(plane[1])
    origins, directions = camera.pixel_rays()
    along = directions @ normal
    t = (offset - origins @ normal) / np.where(np.abs(along) < 1e-9, 1e-9, along)
    points = origins + t[..., None] * directions
    meets = (t > 0) & (np.linalg.norm(points - normal * offset, axis=-1) < reach)
    own = cv2.GaussianBlur(np.asarray(image[:, :, :3], np.float32), (0, 0), blur_px)
    flat = points.reshape(-1, 3)
    seen_by_others = []
    for other_camera, other_image in others:
        xy, depth = other_camera.project(flat)
        xy = np.nan_to_num(xy, nan=-1e4, posinf=-1e4, neginf=-1e4).reshape(meets.shape + (2,)).astype(np.float32)
        other = cv2.GaussianBlur(np.asarray(other_image[:, :, :3], np.float32), (0, 0), blur_px)
        seen = cv2.remap(other, xy[..., 0], xy[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=(-1.0, -1.0, -1.0))
        valid = meets & (depth.reshape(meets.shape) > 0) & (seen[..., 0] >= 0)
        if valid.sum() < 100:
            continue
        # Exposure: scale the other's colours to this photo's on what both see (mostly floor).
        gain = np.median(own[valid], axis=0) / np.maximum(np.median(seen[valid], axis=0), 1.0)
        seen_by_others.append((seen * gain, valid))
    return FloorSight(own, meets, points, seen_by_others)


def off_floor_evidence(disagreement: np.ndarray, threshold: float, specks_px: int = 1) -> np.ndarray:
    """Bool: pixels whose disagreement with the floor is above `threshold`, without specks (an
    opening of `specks_px`): what cannot be the floor."""
    strong = np.nan_to_num(disagreement, nan=0.0) > threshold
    if specks_px > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * specks_px + 1, 2 * specks_px + 1))
        strong = cv2.morphologyEx(strong.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0
    return strong
