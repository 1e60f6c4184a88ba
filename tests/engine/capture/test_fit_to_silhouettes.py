"""The world re-fitted to the masks' hull when an object rises out of the ball (a bottle whose cap
carries no sparse points), and left alone when it fits; and sized by the hull outright when there were
no sparse points at all (imported poses)."""

import numpy as np

from lirm.engine.cameras import orbit_camera
from lirm.engine.capture.fit_to_silhouettes import (fit_world_to_silhouettes, moved_camera, moved_normalization,
                                                     size_world_from_silhouettes)
from lirm.engine.capture.normalize import Normalization

PLANE_Z = -0.85


def _cylinder_masks(top: float, radius: float = 0.35, views: int = 12, size=(160, 120), elevations=(30.0,)):
    """Exact masks of an upright cylinder standing on z = PLANE_Z, seen from a ring of cameras 30
    degrees above it: a ray hits it where its stretch inside the infinite cylinder meets the slab
    between the plane and the top (both convex)."""
    w, h = size
    cameras, masks = {}, {}
    for i in range(views):
        cam = orbit_camera(360.0 * i / views, elevations[i % len(elevations)], 4.5, w, h, 45.0)
        o, d = cam.pixel_rays()
        a = d[..., 0] ** 2 + d[..., 1] ** 2
        b = 2 * (o[..., 0] * d[..., 0] + o[..., 1] * d[..., 1])
        c = o[..., 0] ** 2 + o[..., 1] ** 2 - radius**2
        disc = b * b - 4 * a * c
        root = np.sqrt(np.maximum(disc, 0.0))
        t0, t1 = (-b - root) / (2 * a), (-b + root) / (2 * a)
        s0, s1 = (PLANE_Z - o[..., 2]) / d[..., 2], (top - o[..., 2]) / d[..., 2]
        lo = np.maximum(np.maximum(t0, np.minimum(s0, s1)), 0.0)
        hi = np.minimum(t1, np.maximum(s0, s1))
        hit = (disc > 0) & (lo < hi)
        fid = f"{i:04d}"
        cameras[fid], masks[fid] = cam, np.where(hit, 255, 0).astype(np.uint8)
    return cameras, masks


def _normalization(scale: float = 2.0) -> Normalization:
    world_from_source = np.eye(4)
    world_from_source[:3, :3] *= scale
    world_from_source[:3, 3] = [0.1, -0.2, 0.3]
    return Normalization(world_from_source, np.zeros(3), 0.85 / scale, np.array([0.0, 0.0, 1.0]), 100,
                         plane=(np.array([0.0, 0.0, 1.0]), PLANE_Z), plane_margin=0.05)


def test_a_tall_object_is_brought_inside_the_ball_and_its_masks_stay_true():
    cameras, masks = _cylinder_masks(top=1.1)
    norm = _normalization()
    fit = fit_world_to_silhouettes(masks, cameras, norm, target_radius=1.0, fill=0.85, search_radius=1.0 / 0.85)
    assert fit is not None and fit.moved
    # The hull's top: the cylinder's or above (a ring of views 30 degrees up cannot carve the middle of
    # a flat top down to it), within the ball the masks were searched in.
    assert 1.1 <= fit.top <= 1.0 / 0.85 + 1e-9
    # After the move the cylinder stands on the moved plane and its top is inside the ball, with room.
    moved_top = fit.scale * (1.1 - fit.shift[2])
    moved_bottom = fit.scale * (PLANE_Z - fit.shift[2])
    assert 0.7 < moved_top < 0.95 and -0.95 < moved_bottom < -0.75
    corner = np.array([0.35, 0.0, 1.1])
    assert np.linalg.norm(fit.scale * (corner - fit.shift)) < 1.0
    # Masks are pixels: every world point projects where it did, through the moved cameras.
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (50, 3))
    for fid, cam in cameras.items():
        moved = moved_camera(cam, fit.scale, fit.shift)
        before, _ = cam.project(points)
        after, _ = moved.project(fit.scale * (points - fit.shift))
        np.testing.assert_allclose(after, before, atol=1e-6)
    # The normalisation records the move: source points land where the moved world has them, and
    # the plane and its margin follow.
    moved_norm = moved_normalization(norm, fit.scale, fit.shift)
    source = rng.uniform(-1, 1, (20, 3))
    np.testing.assert_allclose(moved_norm.apply_to_points(source),
                               fit.scale * (norm.apply_to_points(source) - fit.shift), atol=1e-9)
    np.testing.assert_allclose(moved_norm.plane[1], moved_bottom, atol=1e-9)
    assert moved_norm.plane_margin == 0.05 * fit.scale
    np.testing.assert_allclose(moved_norm.apply_to_points(moved_norm.center_source[None]), [[0.0, 0.0, 0.0]], atol=1e-9)


def test_an_object_that_fits_is_left_alone_and_nothing_without_a_plane():
    cameras, masks = _cylinder_masks(top=0.8)
    norm = _normalization()
    fit = fit_world_to_silhouettes(masks, cameras, norm, target_radius=1.0, fill=0.85, search_radius=1.0 / 0.85)
    assert fit is not None and not fit.moved and fit.scale == 1.0
    assert 0.75 < fit.top <= 1.0
    wall = Normalization(norm.world_from_source, np.zeros(3), 1.0, np.array([0.0, 0.0, 1.0]), 100, plane=None)
    assert fit_world_to_silhouettes(masks, cameras, wall, 1.0, 0.85, 1.0 / 0.85) is None
    wall.plane = (np.array([1.0, 0.0, 0.0]), -0.85)  # a wall: its hull's depth is not the object's
    tall_cameras, tall_masks = _cylinder_masks(top=1.1)
    assert fit_world_to_silhouettes(tall_masks, tall_cameras, wall, 1.0, 0.85, 1.0 / 0.85) is None
    two = dict(list(masks.items())[:2])
    assert fit_world_to_silhouettes(two, cameras, norm, 1.0, 0.85, 1.0 / 0.85) is None


def test_a_world_sized_from_the_cameras_alone_is_sized_from_the_masks():
    """Imported poses and no sparse points: normalisation guessed the size from the cameras. Whether the
    guess made the object 2.5 times too large or too small, the hull moves it into the ball, filling it."""
    top = 0.6
    cameras, masks = _cylinder_masks(top=top, views=18, elevations=(-15.0, 20.0, 50.0))
    rims = np.array([[0.35 * np.cos(a), 0.35 * np.sin(a), z] for a in np.linspace(0, 2 * np.pi, 24) for z in (PLANE_Z, top)])
    middle = np.array([0.0, 0.0, 0.5 * (PLANE_Z + top)])
    for guess in (2.5, 0.4):
        offset = np.array([0.1, -0.2, 0.05])
        guessed = {f: moved_camera(c, guess, offset) for f, c in cameras.items()}  # x -> guess * (x - offset)
        fit = size_world_from_silhouettes(masks, guessed, target_radius=1.0, fill=0.85, search_radius=1.0 / 0.85,
                                          trusted_masks=True)
        assert fit is not None and fit.moved
        to_world = lambda p: fit.scale * (guess * (p - offset) - fit.shift)  # noqa: E731
        reach = np.linalg.norm(to_world(rims), axis=1).max()
        assert 0.7 < reach < 0.9, (guess, reach)  # inside the ball, near fill * R: the hull is a voxel fatter
        assert np.linalg.norm(to_world(middle)) < 0.1, guess
    assert size_world_from_silhouettes(dict(list(masks.items())[:2]), cameras, 1.0, 0.85, 1.0 / 0.85) is None



def test_stray_voxels_do_not_size_the_world():
    """Where few views overlap, a few voxels can survive the carving far from the object; the
    object's own pieces stay, down to a twentieth of the largest."""
    from lirm.engine.capture.fit_to_silhouettes import _drop_specks
    from lirm.engine.capture.visual_hull import VoxelHull

    grid = np.zeros((40, 40, 40), bool)
    grid[10:20, 10:20, 10:20] = True  # the object, 1000 voxels
    grid[25:29, 10:20, 10:14] = True  # a separate part of it, 160 voxels
    grid[35, 35, 35] = grid[2, 30, 5] = True  # strays
    hull = VoxelHull(grid.copy(), 1.0)
    _drop_specks(hull)
    assert hull.num_occupied == 1160
    assert not hull.occupancy[35, 35, 35] and not hull.occupancy[2, 30, 5]
