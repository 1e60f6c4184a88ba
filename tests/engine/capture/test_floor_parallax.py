"""The floor's parallax (floor_parallax.py): a cylinder on a mottled floor, painted with the floor's own
mottle, so that colour alone cannot tell them apart. What stands on the floor
disagrees with what the other views see at the floor point behind it; the floor agrees."""

from dataclasses import replace

import cv2
import numpy as np

from lirm.engine.cameras import nearest_cameras, orbit_camera
from lirm.engine.capture.auto_mask import AutoMaskConfig, automatic_masks
from lirm.engine.capture.floor_parallax import floor_agreement, floor_disagreement, off_floor_evidence
from lirm.engine.capture.masks import mask_iou

FLOOR_Z = -0.6
PALE = np.array([160.0, 158.0, 150.0])


def _floor_colour(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth mottle (random colours 0.2 units apart, bicubic) over [-6, 6]^2."""
    rng = np.random.default_rng(7)
    cells = rng.uniform(-60, 60, (64, 64, 3)).astype(np.float32) + PALE.astype(np.float32)
    texture = cv2.resize(cells, (1024, 1024), interpolation=cv2.INTER_CUBIC)
    u = ((x + 6.0) / 12.0 * 1023).astype(np.float32)
    v = ((y + 6.0) / 12.0 * 1023).astype(np.float32)
    return cv2.remap(texture, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT).astype(np.float64)


def _scene(views: int = 10, size=(240, 180), radius: float = 0.3, top: float = 0.7, bands: bool = False):
    """`bands`: the cylinder painted in horizontal bands of the floor's colours instead (a label's print)."""
    w, h = size[0] * 2, size[1] * 2  # rendered at twice the size, then averaged down
    images, cameras, truth = {}, {}, {}
    for i in range(views):
        cam = orbit_camera(360.0 * i / views, 30.0, 4.0, w, h, 50.0)
        o, d = cam.pixel_rays()
        # Floor hit.
        t_floor = np.where(d[..., 2] < 0, (FLOOR_Z - o[..., 2]) / np.minimum(d[..., 2], -1e-9), np.inf)
        # Cylinder hit: the ray's stretch inside the infinite cylinder meets the slab [floor, top].
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = 2 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1])
        c = o[..., 0] ** 2 + o[..., 1] ** 2 - radius**2
        disc = b * b - 4 * a * c
        root = np.sqrt(np.maximum(disc, 0))
        t0, t1 = (-b - root) / (2 * a), (-b + root) / (2 * a)
        s0, s1 = (FLOOR_Z - o[..., 2]) / d[..., 2], (top - o[..., 2]) / d[..., 2]
        lo = np.maximum(t0, np.minimum(s0, s1))
        hi = np.minimum(t1, np.maximum(s0, s1))
        hit = (disc > 0) & (lo < hi) & (lo > 0)
        p = o + np.where(np.isfinite(t_floor), t_floor, 0.0)[..., None] * d
        image = np.where(np.isfinite(t_floor)[..., None], _floor_colour(p[..., 0], p[..., 1]), 120.0)
        # The cylinder: painted with the floor's own mottle, so that its colours are the floor's.
        q = o + np.where(hit, lo, 0.0)[..., None] * d
        paint = _floor_colour(np.zeros_like(q[..., 2]), q[..., 2] * 6.0) if bands else \
            _floor_colour(np.arctan2(q[..., 1], q[..., 0]) * 1.5, q[..., 2] * 3.0)
        image = np.where(hit[..., None], paint, image)
        fid = f"{i:04d}"
        images[fid] = np.clip(cv2.resize(image, size, interpolation=cv2.INTER_AREA), 0, 255).astype(np.uint8)
        cameras[fid] = orbit_camera(360.0 * i / views, 30.0, 4.0, size[0], size[1], 50.0)
        truth[fid] = np.where(cv2.resize(hit.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5, 255, 0).astype(np.uint8)
    return images, cameras, truth


PLANE = (np.array([0.0, 0.0, 1.0]), FLOOR_Z)


def test_what_stands_on_the_floor_disagrees_with_it_and_the_floor_agrees():
    images, cameras, truth = _scene()
    others = [(cameras[g], images[g]) for g in nearest_cameras(cameras, "0000", 4)]
    d = floor_disagreement(cameras["0000"], images["0000"], others, PLANE, blur_px=1.5 * 240 / 640)
    obj = truth["0000"] > 0
    floor = ~obj & ~np.isnan(d)
    assert np.nanpercentile(d[floor], 99) < 30.0
    # The cylinder's upper half stands well above the floor: it disagrees.
    ys, _ = np.nonzero(obj)
    upper = obj & (np.arange(obj.shape[0])[:, None] < np.median(ys))
    assert np.nanmedian(d[upper]) > 40.0
    evidence = off_floor_evidence(d, 48.0)
    assert evidence[upper].mean() > 0.25 and evidence[floor].mean() < 0.001
    # Above the horizon the ray never meets the floor: nothing is known there.
    assert np.isnan(d[0]).all()


def test_the_floor_evidence_finds_an_object_coloured_like_the_floor():
    images, cameras, truth = _scene()
    config = AutoMaskConfig(hull_resolution=48, ball_probable_fraction=0.8)
    without = automatic_masks(images, cameras, radius=1.0, config=AutoMaskConfig(
        hull_resolution=48, ball_probable_fraction=0.8, floor_parallax_threshold=0), support_plane=PLANE)
    with_floor = automatic_masks(images, cameras, radius=1.0, config=config, support_plane=PLANE)
    iou_without = np.mean([mask_iou(without[f], truth[f]) for f in cameras])
    iou_with = np.mean([mask_iou(with_floor[f], truth[f]) for f in cameras])
    # Colour alone loses the camouflaged cylinder altogether; the floor's parallax finds most of it.
    assert iou_without < 0.3 and iou_with > 0.7, (iou_with, iou_without)


# A square frame standing on a post, its opening (0.6 x 0.6) well above the floor: the floor is seen
# through it from the views that face it. (min corner, max corner) of each box.
FRAME = [((-0.5, -0.06, -0.3), (0.5, 0.06, -0.1)), ((-0.5, -0.06, 0.5), (0.5, 0.06, 0.7)),
         ((-0.5, -0.06, -0.1), (-0.3, 0.06, 0.5)), ((0.3, -0.06, -0.1), (0.5, 0.06, 0.5)),
         ((-0.1, -0.06, -0.6), (0.1, 0.06, -0.3))]


def _first_box_hit(o: np.ndarray, d: np.ndarray, boxes) -> np.ndarray:
    """Per ray, the distance to the nearest box it enters (slab method), inf where it meets none."""
    nearest = np.full(o.shape[:-1], np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for lo, hi in boxes:
            t_lo, t_hi = (np.asarray(lo) - o) / d, (np.asarray(hi) - o) / d
            enter = np.minimum(t_lo, t_hi).max(axis=-1)
            leave = np.maximum(t_lo, t_hi).min(axis=-1)
            hit = (enter < leave) & (enter > 0)
            nearest = np.where(hit & (enter < nearest), enter, nearest)
    return nearest


def _frame_scene(views: int = 12, size=(240, 180)):
    """The frame, painted with the floor's own mottle (colour cannot tell them apart), on the floor."""
    w, h = size[0] * 2, size[1] * 2
    images, cameras, truth = {}, {}, {}
    for i in range(views):
        azimuth = 360.0 * i / views + 15.0  # none edge-on
        cam = orbit_camera(azimuth, 30.0, 4.0, w, h, 50.0)
        o, d = cam.pixel_rays()
        t_floor = np.where(d[..., 2] < 0, (FLOOR_Z - o[..., 2]) / np.minimum(d[..., 2], -1e-9), np.inf)
        p = o + np.where(np.isfinite(t_floor), t_floor, 0.0)[..., None] * d
        image = np.where(np.isfinite(t_floor)[..., None], _floor_colour(p[..., 0], p[..., 1]), 120.0)
        t_box = _first_box_hit(o, d, FRAME)
        hit = np.isfinite(t_box)
        q = o + np.where(hit, t_box, 0.0)[..., None] * d
        image = np.where(hit[..., None], _floor_colour(q[..., 0] * 3.0 + q[..., 1] * 3.0, q[..., 2] * 3.0), image)
        fid = f"{i:04d}"
        images[fid] = np.clip(cv2.resize(image, size, interpolation=cv2.INTER_AREA), 0, 255).astype(np.uint8)
        cameras[fid] = orbit_camera(azimuth, 30.0, 4.0, size[0], size[1], 50.0)
        truth[fid] = np.where(cv2.resize(hit.astype(np.float32), size, interpolation=cv2.INTER_AREA) > 0.5, 255, 0).astype(np.uint8)
    return images, cameras, truth


def test_the_floor_seen_through_an_opening_agrees_and_the_object_does_not():
    images, cameras, truth = _frame_scene()
    f = "0000"
    others = [(cameras[g], images[g]) for g in nearest_cameras(cameras, f, 4)]
    agreement = floor_agreement(cameras[f], images[f], others, PLANE, blur_px=1.5 * 240 / 640)
    obj = cv2.erode(truth[f], np.ones((5, 5), np.uint8)) > 0
    floor = (cv2.dilate(truth[f], np.ones((5, 5), np.uint8)) == 0) & ~np.isnan(agreement)
    strong = np.nan_to_num(agreement, nan=-1.0) > 0.8
    # The floor (beside the frame and through its opening) agrees where its mottle is distinct enough;
    # the frame, painted like it, does not.
    assert strong[floor].mean() > 0.25 and strong[obj].mean() < 0.005, (strong[floor].mean(), strong[obj].mean())


def test_a_print_in_bands_does_not_pass_for_the_floor():
    """Horizontal bands look the same wherever the parallax of cameras round the object moves them;
    only a match better than the patch moved beside it counts (a label's bands on a bottle were taken
    for the floor before, and GrabCut took the label away)."""
    images, cameras, truth = _scene(views=16, radius=0.9, bands=True)  # wide: it hides the floor behind it from the neighbours
    f = "0000"
    others = [(cameras[g], images[g]) for g in nearest_cameras(cameras, f, 4)]
    obj = cv2.erode(truth[f], np.ones((5, 5), np.uint8)) > 0
    ys = np.nonzero(obj)[0]
    upper = obj & (np.arange(obj.shape[0])[:, None] < np.percentile(ys, 60))  # not the base
    blur = 1.5 * 240 / 640
    strict = np.nan_to_num(floor_agreement(cameras[f], images[f], others, PLANE, blur_px=blur), nan=-1.0) > 0.8
    loose = np.nan_to_num(floor_agreement(cameras[f], images[f], others, PLANE, blur_px=blur, distinct_by=-2.0), nan=-1.0) > 0.8
    assert loose[upper].sum() >= 20 and strict[upper].sum() == 0, (loose[upper].sum(), strict[upper].sum())


def test_the_masks_keep_the_floor_seen_through_an_opening():
    images, cameras, truth = _frame_scene()
    config = AutoMaskConfig(hull_resolution=48, ball_probable_fraction=0.8)
    without = automatic_masks(images, cameras, radius=1.0, config=replace(config, floor_agreement_threshold=0),
                              support_plane=PLANE)
    with_floor = automatic_masks(images, cameras, radius=1.0, config=config, support_plane=PLANE)

    def opening_taken(masks) -> float:
        """Of the floor seen through the opening (the truth's holes, all views' pixels), the share the
        masks call object."""
        taken = holes_seen = 0
        for g, m in masks.items():
            outside = (truth[g] > 0).astype(np.uint8)
            cv2.floodFill(outside, np.zeros((outside.shape[0] + 2, outside.shape[1] + 2), np.uint8), (0, 0), 1)
            holes = outside == 0  # what the border's background does not reach
            taken += int((m[holes] > 0).sum())
            holes_seen += int(holes.sum())
        return taken / holes_seen

    # Every view's first pass, and so the hull, takes the opening for object; the floor's agreement
    # opens it where the views face it (views nearly edge-on see a slit narrower than its window).
    before, after = opening_taken(without), opening_taken(with_floor)
    iou_before = np.mean([mask_iou(without[g], truth[g]) for g in cameras])
    iou_after = np.mean([mask_iou(with_floor[g], truth[g]) for g in cameras])
    assert before > 0.9 and after < 0.15 and iou_after > iou_before + 0.05, (before, after, iou_before, iou_after)
