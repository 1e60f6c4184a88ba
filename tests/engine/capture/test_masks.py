"""Mask sources, mask checks, the visual hull and the propagation of a user's mask fix."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from lirm.engine.cameras import Camera, orbit_camera
from lirm.engine.capture.masks import (
    check_mask,
    load_user_masks,
    mask_from_alpha,
    mask_iou,
    propagate_mask_fix,
    soft_alpha,
)
from lirm.engine.capture.visual_hull import carve_visual_hull, project_hull, sphere_silhouette


# --------------------------------------------------------------------------------------------------
# Alpha


def test_mask_from_alpha_thresholds_at_one_half():
    rgba = np.zeros((4, 256, 4), np.uint8)
    rgba[:, :, 3] = np.arange(256)
    m = mask_from_alpha(rgba)
    assert m.dtype == np.uint8 and m.shape == (4, 256)
    assert set(np.unique(m)) == {0, 255}
    assert (m[0] == 255).tolist() == (np.arange(256) > 127).tolist()
    # 16-bit and float alpha mean the same coverage.
    assert np.array_equal(mask_from_alpha((rgba.astype(np.uint16) * 257)), m)
    assert np.array_equal(mask_from_alpha(rgba.astype(np.float32) / 255.0), m)
    soft = soft_alpha(rgba)
    assert soft.dtype == np.float32 and soft.min() == 0.0 and soft.max() == 1.0
    with pytest.raises(ValueError, match="RGBA"):
        mask_from_alpha(np.zeros((4, 4, 3), np.uint8))


# --------------------------------------------------------------------------------------------------
# User mask folders


def _write(path, image) -> None:
    ok, buf = cv2.imencode(path.suffix, image)
    assert ok
    path.write_bytes(buf.tobytes())


def test_load_user_masks_matches_names_resizes_and_reports(tmp_path):
    folder = tmp_path / "masks"
    folder.mkdir()
    small = np.zeros((30, 40), np.uint8)
    small[10:20, 10:30] = 255
    _write(folder / "IMG_0001.png", small)  # stem + .png, half the photo's size
    big = np.zeros((60, 80), np.uint8)
    big[:, :40] = 200
    _write(folder / "img_0002.jpg.png", big)  # full name + .png, other case
    cutout = np.zeros((60, 80, 4), np.uint8)
    cutout[:, :, :3] = 255  # white everywhere: only the alpha says where the object is
    cutout[20:40, 20:60, 3] = 255
    _write(folder / "photo3_mask.png", cutout)
    (folder / "broken.png").write_bytes(b"not an image")
    _write(folder / "stray.png", big)

    names = {"0001": "IMG_0001.JPG", "0002": "IMG_0002.jpg", "0003": "photo3.png",
             "0004": "missing.jpg", "0005": "broken.jpg"}
    sizes = {f: (80, 60) for f in names}
    masks, reports = load_user_masks(folder, names, sizes)

    assert sorted(masks) == ["0001", "0002", "0003"]
    for m in masks.values():
        assert m.shape == (60, 80) and m.dtype == np.uint8 and set(np.unique(m)) <= {0, 255}
    assert np.count_nonzero(masks["0001"]) == 20 * 40  # nearest-neighbour x2 keeps it binary
    assert masks["0002"][:, :40].all() and not masks["0002"][:, 40:].any()
    assert np.count_nonzero(masks["0003"]) == 20 * 40

    by_frame = {r.frame_id: r for r in reports if r.frame_id}
    assert by_frame["0001"].accepted and "resized from 40x30" in by_frame["0001"].reason
    assert by_frame["0002"].accepted and by_frame["0002"].path.name == "img_0002.jpg.png"
    assert not by_frame["0004"].accepted and "missing.jpg" in by_frame["0004"].reason
    assert not by_frame["0005"].accepted and "could not be read" in by_frame["0005"].reason
    assert by_frame["0005"].path.name == "broken.png"
    stray = [r for r in reports if r.frame_id is None]
    assert [r.path.name for r in stray] == ["stray.png"] and "matches no photo" in stray[0].reason

    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_user_masks(tmp_path / "nowhere", names)


# --------------------------------------------------------------------------------------------------
# Checks


def test_check_mask_flags_empty_full_and_border_masks():
    h, w = 100, 120
    ok = np.zeros((h, w), np.uint8)
    ok[20:80, 30:90] = 255
    assert check_mask(ok) is None
    assert "empty" in check_mask(np.zeros((h, w), np.uint8))
    tiny = np.zeros((h, w), np.uint8)
    tiny[50, 50:55] = 255  # 5 pixels < 0.1% of 12000
    assert "empty" in check_mask(tiny)
    assert "whole frame" in check_mask(np.full((h, w), 255, np.uint8))
    frame = np.zeros((h, w), np.uint8)
    frame[:, :10] = frame[:, -10:] = frame[:10] = frame[-10:] = 255  # background inside a frame
    assert "all four sides" in check_mask(frame)
    three = ok.copy()
    three[:, :60] = 255  # an object cut by the top, bottom and left edges is plausible
    assert check_mask(three) is None


# --------------------------------------------------------------------------------------------------
# Visual hull of a sphere

CENTER = np.array([0.1, -0.05, 0.05])
R_SPHERE = 0.5


def _sphere_truth(cam: Camera, center=CENTER, radius=R_SPHERE) -> np.ndarray:
    """Exact silhouette by ray-sphere intersection at every pixel centre (independent of the
    projection code under test; handles distortion through rays_at)."""
    o, d = cam.pixel_rays()
    oc = o - center
    b = np.einsum("hwc,hwc->hw", oc, d)
    disc = b * b - (np.einsum("hwc,hwc->hw", oc, oc) - radius * radius)
    return np.where((disc >= 0) & (b < 0), 255, 0).astype(np.uint8)


def _cameras(n: int = 8, distance: float = 3.0) -> dict[str, Camera]:
    cams = {}
    for i in range(n):
        cam = orbit_camera(i * 360.0 / n + 7.0, 30.0 * (-1) ** i, distance, 480, 360, 40.0)
        if i % 3 == 1:  # some lenses with distortion: projection must go through it
            cam = Camera(cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy, cam.c2w, [-0.15, 0.03, 0.001, -0.001])
        cams[f"{i + 1:04d}"] = cam
    return cams


def test_visual_hull_of_a_sphere_contains_it_and_reprojects_tightly():
    cams = _cameras()
    masks = {f: _sphere_truth(c) for f, c in cams.items()}
    # The grid spans the object's bounding ball, as after normalisation.
    hull = carve_visual_hull(masks, cams, radius=0.75, resolution=128)

    rng = np.random.default_rng(0)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    inside = CENTER + d * R_SPHERE * rng.random((20000, 1)) ** (1 / 3)
    assert hull.contains(inside).all(), "the hull must contain the object"
    volume = hull.num_occupied * hull.voxel_size**3
    sphere_volume = 4 / 3 * math.pi * R_SPHERE**3
    assert volume < 1.5 * sphere_volume, f"hull {volume:.3f} vs sphere {sphere_volume:.3f}"
    assert not hull.contains(CENTER + d * (R_SPHERE + 0.25)).any()

    ious = [mask_iou(project_hull(hull, cams[f]), masks[f]) for f in cams]
    assert min(ious) >= 0.9, ious
    # The ball's projection helper agrees with the exact silhouette too.
    assert mask_iou(sphere_silhouette(cams["0001"], R_SPHERE, CENTER), masks["0001"]) > 0.97


def test_visual_hull_tolerates_a_bad_mask_unless_told_to_trust_it():
    cams = _cameras(10)
    masks = {f: _sphere_truth(c) for f, c in cams.items()}
    bad = dict(masks)
    bad["0003"] = np.zeros_like(masks["0003"])  # one wrong (empty) mask
    strict = carve_visual_hull(bad, cams, radius=1.0, resolution=48, min_views_fraction=1.0)
    tolerant = carve_visual_hull(bad, cams, radius=1.0, resolution=48, min_views_fraction=0.9)
    assert strict.is_empty
    # One miss in ten views is allowed, and the bad view spends it everywhere it looks: what is
    # left is exactly what the nine good views agree on.
    others = {f: m for f, m in masks.items() if f != "0003"}
    assert np.array_equal(tolerant.occupancy, carve_visual_hull(others, cams, 1.0, 48, 1.0).occupancy)
    assert mask_iou(project_hull(tolerant, cams["0001"]), masks["0001"]) > 0.7
    # ...unless that view is the one the user vouches for.
    assert carve_visual_hull(bad, cams, 1.0, 48, 0.9, strict_frames=["0003"]).is_empty


# --------------------------------------------------------------------------------------------------
# Propagating a fix


def test_propagate_mask_fix_removes_a_blob_from_the_other_views():
    # Far enough that every view sees the whole ball the object is in.
    cams = _cameras(distance=3.6)
    truth = {f: _sphere_truth(c) for f, c in cams.items()}
    # Something beside the object (a mug next to it, say) that every automatic mask took in.
    blob = {f: _sphere_truth(c, np.array([0.8, 0.0, 0.05]), 0.12) for f, c in cams.items()}
    wrong = {f: np.maximum(truth[f], blob[f]) for f in cams}
    extra = {f: (blob[f] > 0) & (truth[f] == 0) for f in cams}  # what is wrong in each mask

    # The user removes it in a view where it stands clearly apart from the object (a gap of a few
    # voxels: what the fixed view cannot tell from the object within its slack stays).
    fixed = "0001"
    new, changed = propagate_mask_fix(fixed, truth[fixed], cams, wrong, radius=0.95)
    assert np.array_equal(new[fixed], truth[fixed])

    voxel_px = 2 * 0.95 / 96 * cams[fixed].fx / 3.6  # default resolution 96, seen from 3.6

    def thickness(region: np.ndarray) -> float:
        return float(cv2.distanceTransform(np.pad(region.astype(np.uint8), 1), cv2.DIST_L2, 5).max())

    # Where the blob shows as more than a rim, it goes; a rim along the object within the hull's
    # voxel-sized slack may stay.
    clear = [f for f in cams if f != fixed and thickness(extra[f]) > 3 * voxel_px]
    assert len(clear) >= 3 and set(clear) <= set(changed), (clear, changed)
    for f in cams:
        left = (new[f] > 0) & extra[f]
        if f in clear:
            assert np.count_nonzero(left) < 0.2 * np.count_nonzero(extra[f]), f"view {f}"
        dist = cv2.distanceTransform((truth[f] == 0).astype(np.uint8), cv2.DIST_L2, 5)
        # (The conservative hull is up to ~2 voxels fatter than the object, more where a view
        # looks along that rim.)
        assert dist[left].max(initial=0) < 4 * voxel_px, f"view {f}: blob left away from the object"
        # The object itself is not eaten into.
        lost = np.count_nonzero((truth[f] > 0) & (new[f] == 0))
        assert lost <= 0.002 * np.count_nonzero(truth[f]), f"view {f}: {lost} object pixels lost"

    # Masks that already agree with the fix are left alone.
    same, changed = propagate_mask_fix(fixed, truth[fixed], cams, truth, radius=0.95)
    assert changed == []
    assert all(np.array_equal(same[f], truth[f]) for f in cams)
