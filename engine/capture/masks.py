"""Object masks: from alpha channels, from the user's mask files, checks, and fix propagation.

A mask is a uint8 (H, W) image at the working image's size, 255 = object, 0 = background. Views are
identified by frame id (see records.py). Automatic masks for photos with real backgrounds are in
auto_mask.py; the multi-view geometry (visual hull) is in visual_hull.py.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import math

import cv2
import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.capture.records import FileReport
from lirm.engine.capture.visual_hull import VoxelHull, carve_visual_hull, project_hull

__all__ = [
    "MASK_SUFFIXES",
    "mask_from_alpha",
    "soft_alpha",
    "load_user_masks",
    "read_mask_file",
    "check_mask",
    "cut_by_border",
    "mask_iou",
    "remove_regions_outside",
    "propagate_mask_fix",
]

# Image extensions a user's mask file may have (matched case-insensitively).
MASK_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp")

# check_mask thresholds, as fractions of the image area.
_EMPTY_FRACTION = 0.001
_FULL_FRACTION = 0.98


def _alpha_channel(rgba: np.ndarray) -> np.ndarray:
    a = np.asarray(rgba)
    if a.ndim != 3 or a.shape[2] != 4:
        raise ValueError(f"expected an RGBA image of shape (H, W, 4), got {a.shape}")
    return a[:, :, 3]


def soft_alpha(rgba: np.ndarray) -> np.ndarray:
    """float32 (H, W) alpha in [0, 1] of an RGBA image (uint8, uint16 or float in [0, 1])."""
    alpha = _alpha_channel(rgba)
    if alpha.dtype == np.uint8:
        return alpha.astype(np.float32) / 255.0
    if alpha.dtype == np.uint16:
        return alpha.astype(np.float32) / 65535.0
    return np.clip(alpha.astype(np.float32), 0.0, 1.0)


def mask_from_alpha(rgba: np.ndarray) -> np.ndarray:
    """uint8 mask of an RGBA image: object where alpha is above one half (> 127 for 8 bits)."""
    return np.where(soft_alpha(rgba) > 127.5 / 255.0, 255, 0).astype(np.uint8)


def read_mask_file(path: str | Path) -> np.ndarray | None:
    """A mask from an image file, or None when it cannot be read.

    Grey or colour files: object where the brightness is above one half. Files with an alpha
    channel that is not fully opaque use the alpha (a cut-out PNG is a mask too).
    """
    data = np.fromfile(str(path), dtype=np.uint8) if Path(path).is_file() else None
    if data is None or data.size == 0:
        return None
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if img is None:
        return None
    if img.dtype == np.uint16:
        img = (img // 257).astype(np.uint8)
    elif img.dtype != np.uint8:
        img = np.clip(img.astype(np.float64) * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    if img.ndim == 3 and img.shape[2] == 4 and img[:, :, 3].min() < 255:
        grey = img[:, :, 3]
    elif img.ndim == 3:
        grey = cv2.cvtColor(img[:, :, :3], cv2.COLOR_BGR2GRAY)
    else:
        grey = img
    return np.where(grey > 127, 255, 0).astype(np.uint8)


def _candidate_names(image_name: str) -> list[str]:
    """Mask file names that belong to an image, most specific first (lower case)."""
    name = Path(image_name).name.lower()
    stem = Path(name).stem
    out: list[str] = []
    for ext in MASK_SUFFIXES:
        out += [f"{name}{ext}", f"{stem}{ext}", f"{stem}_mask{ext}", f"{stem}-mask{ext}", f"{stem}.mask{ext}"]
    return list(dict.fromkeys(out))


def load_user_masks(
    folder: str | Path,
    frame_names: Mapping[str, str] | Sequence[str],
    sizes: Mapping[str, tuple[int, int]] | None = None,
) -> tuple[dict[str, np.ndarray], list[FileReport]]:
    """Read the user's mask files for the frames.

    frame_names: frame id -> the image's file name (the original photo's or the working copy's
    basename); a plain list means the names are the ids. A mask matches an image by basename,
    case-insensitively: `name.png`, `name.jpg.png` (the full image name plus a mask extension),
    `name_mask.png`, `name-mask.png` or `name.mask.png`, with any of MASK_SUFFIXES.
    sizes: frame id -> (width, height) of the working image; a mask of another size is resized
    with nearest-neighbour sampling (it stays binary) and the report says so.

    Returns (masks by frame id, one FileReport per frame plus one per image file in the folder that
    matched no frame). Reports of missing or unreadable masks have accepted=False and a reason that
    names the files looked for; a mask that check_mask flags is accepted with the warning as reason.
    """
    folder = Path(folder)
    names = dict(frame_names) if isinstance(frame_names, Mapping) else {n: n for n in frame_names}
    if not folder.is_dir():
        raise FileNotFoundError(f"mask folder {folder} does not exist; choose the folder holding the mask images")
    files = {p.name.lower(): p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MASK_SUFFIXES}
    used: set[str] = set()
    masks: dict[str, np.ndarray] = {}
    reports: list[FileReport] = []
    for frame_id, image_name in names.items():
        candidates = _candidate_names(image_name)
        hit = next((c for c in candidates if c in files), None)
        if hit is None:
            stem = Path(image_name).stem
            reports.append(FileReport(
                folder / f"{stem}.png", False,
                f"no mask for {Path(image_name).name} (looked for {stem}.png, {Path(image_name).name}.png, "
                f"{stem}_mask.png and other image types)", frame_id,
            ))
            continue
        path = files[hit]
        used.add(hit)
        mask = read_mask_file(path)
        if mask is None:
            reports.append(FileReport(path, False, "could not be read as an image; re-save it as PNG", frame_id))
            continue
        notes = []
        if sizes is not None and frame_id in sizes:
            w, h = sizes[frame_id]
            if mask.shape != (h, w):
                notes.append(f"resized from {mask.shape[1]}x{mask.shape[0]} to {w}x{h}")
                mask = cv2.resize(mask, (int(w), int(h)), interpolation=cv2.INTER_NEAREST)
        problem = check_mask(mask)
        if problem:
            notes.append(problem)
        masks[frame_id] = mask
        reports.append(FileReport(path, True, "; ".join(notes), frame_id))
    for key, path in sorted(files.items()):
        if key not in used:
            reports.append(FileReport(path, False, "matches no photo of the capture", None))
    return masks, reports


def check_mask(mask: np.ndarray) -> str | None:
    """A short message when a mask is probably wrong, None when it looks plausible.

    Flags a mask that is empty (under 0.1% of the image), one that covers the whole frame (over
    98%), and one that touches all four image borders (it most likely contains the background).
    """
    m = np.asarray(mask) > 127
    if m.ndim != 2 or m.size == 0:
        return f"not a single-channel mask (shape {np.asarray(mask).shape})"
    frac = float(m.mean())
    if frac < _EMPTY_FRACTION:
        return "empty: no object found in this view"
    if frac > _FULL_FRACTION:
        return "covers the whole frame: the background was not separated"
    if m[0].any() and m[-1].any() and m[:, 0].any() and m[:, -1].any():
        return "touches the border on all four sides: it probably includes background"
    return None


def cut_by_border(mask: np.ndarray, min_share: float = 0.05) -> str | None:
    """A short message when the object runs out of the picture: the mask covers more than
    `min_share` of an image border's length (a few pixels of contact are a loose outline, not a cut).
    Such a view shows only part of the object, and the cropped view would pretend the rest is empty."""
    m = np.asarray(mask) > 127
    if m.ndim != 2 or m.size == 0:
        return None
    sides = {"top": m[0], "bottom": m[-1], "left": m[:, 0], "right": m[:, -1]}
    cut = [name for name, line in sides.items() if line.mean() > min_share]
    if not cut:
        return None
    return (f"the mask runs out of the picture ({', '.join(cut)} border): the object is cut off (step back next "
            f"time) or the mask took in background")


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two masks (1.0 when both are empty)."""
    a, b = np.asarray(a) > 127, np.asarray(b) > 127
    union = np.count_nonzero(a | b)
    return 1.0 if union == 0 else np.count_nonzero(a & b) / union


def _disc(radius_px: float) -> np.ndarray:
    r = max(int(math.ceil(radius_px)), 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def remove_regions_outside(
    mask: np.ndarray, allowed: np.ndarray, min_thickness_px: float, margin_px: float = 0.0
) -> np.ndarray:
    """Remove from `mask` the parts outside `allowed` that are thicker than `min_thickness_px`.

    The disagreement (mask and not allowed) is split into connected regions; a region goes when
    the largest disc that fits inside it has a radius above `min_thickness_px`. Thin slivers along
    the outline (voxel steps, small pose errors) stay, so a coarse `allowed` never nibbles a good
    outline, while a blob of background goes whole, even where it touches the object.

    `margin_px` says how much bigger than the object `allowed` may be (a conservative hull's
    projection is): next to a removed region, the mask's pixels in that outer margin of `allowed`
    go too, so no rim of the blob is left along the object.
    """
    m = np.asarray(mask) > 127
    ok = np.asarray(allowed) > 127
    extra = (m & ~ok).astype(np.uint8)
    if not extra.any():
        return np.asarray(mask).copy()
    n, labels = cv2.connectedComponents(extra, connectivity=4)
    # Distance to the nearest pixel outside the region (image border counts as outside the mask).
    thick = cv2.distanceTransform(np.pad(extra, 1), cv2.DIST_L2, 5)[1:-1, 1:-1]
    max_thick = np.zeros(n, np.float32)
    np.maximum.at(max_thick, labels.ravel(), thick.ravel())
    drop = max_thick > min_thickness_px
    drop[0] = False
    removed = drop[labels]
    if margin_px > 0 and removed.any():
        core = cv2.erode(ok.astype(np.uint8), _disc(margin_px)) > 0
        near = cv2.dilate(removed.astype(np.uint8), _disc(margin_px + 1.0)) > 0
        removed |= near & m & ok & ~core
    return np.where(m & ~removed, 255, 0).astype(np.uint8)


def _voxel_pixels(hull: VoxelHull, camera: Camera) -> float:
    """Projected size in pixels of one voxel at the distance of the grid's centre."""
    depth = max(float(np.linalg.norm(camera.center)), hull.radius * 1e-3)
    return hull.voxel_size * max(camera.fx, camera.fy) / depth


def propagate_mask_fix(
    fixed_frame: str,
    fixed_mask: np.ndarray,
    cameras: Mapping[str, Camera],
    masks: Mapping[str, np.ndarray],
    radius: float = 1.0,
    resolution: int = 96,
    min_views_fraction: float = 0.9,
) -> tuple[dict[str, np.ndarray], list[str]]:
    """Carry a user's fix of one view's mask over to the other views.

    The rule: carve a visual hull inside the object's ball of `radius` (the normalised world) from
    all masks with the fixed one in place, where the fixed view carves strictly (what the user
    removed is removed from 3D) and the others with the usual `min_views_fraction` tolerance;
    project the hull into every other view; remove from that view's mask each region outside the
    hull's projection that is thicker than a voxel, with its rim along the object (see
    `remove_regions_outside`; thinner slivers are the hull's own coarseness).

    Masks only lose pixels: a region one view has and the hull lacks cannot be object, but a region
    the hull has and a view lacks may be something in front of the object, so nothing is added.
    The fixed view can only remove what it sees: space outside its frame, or within a voxel or two
    of the object in its image, is judged by the other views alone.

    Returns (all masks with `fixed_frame` set to `fixed_mask` and the others updated, the frame
    ids whose masks changed, excluding `fixed_frame`). Frames without a camera are left as they are.
    """
    fixed = np.where(np.asarray(fixed_mask) > 127, 255, 0).astype(np.uint8)
    all_masks = dict(masks)
    all_masks[fixed_frame] = fixed
    if fixed_frame not in cameras:
        raise ValueError(f"frame {fixed_frame!r} has no camera; a fix can only propagate between posed views")
    hull = carve_visual_hull(
        all_masks, cameras, radius=radius, resolution=resolution,
        min_views_fraction=min_views_fraction, strict_frames=[fixed_frame], within_sphere=True,
    )
    changed: list[str] = []
    out = dict(all_masks)
    for frame, mask in all_masks.items():
        if frame == fixed_frame or frame not in cameras:
            continue
        cam = cameras[frame]
        allowed = project_hull(hull, cam)
        vox = _voxel_pixels(hull, cam)
        # The hull is conservative: its outline lies up to about 1.5 voxels (plus a pixel) outside
        # the object, and any disagreement thicker than a voxel is beyond what coarseness explains.
        # The rim trimmed next to a removed region stays within a voxel of the outline, where the
        # hull is almost always at least that loose, so the object itself is not cut.
        new = remove_regions_outside(mask, allowed, max(vox, 2.0), margin_px=vox + 1.0)
        if not np.array_equal(new > 127, np.asarray(mask) > 127):
            out[frame] = new
            changed.append(frame)
    return out, changed
