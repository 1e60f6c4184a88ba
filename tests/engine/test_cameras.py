"""Camera conventions: these tests pin down the project's one camera convention (DESIGN.md section 3)."""

from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest

from lirm.engine.cameras import (
    Camera,
    c2w_to_colmap,
    camera_from_plucker,
    colmap_to_c2w,
    distance_to_cover_sphere,
    focal_to_fov,
    fov_to_focal,
    look_at,
    opencv_to_opengl_c2w,
    opengl_to_opencv_c2w,
    nearest_cameras,
    orbit_camera,
    orbit_cameras,
    plucker_rays,
    qvec_to_rotmat,
    rotmat_to_qvec,
    undistort_normalized,
)

# Moderate real-lens distortions: 4 (COLMAP OPENCV), 5 and 8 (rational) coefficients.
DIST4 = np.array([-0.12, 0.03, 0.001, -0.0015])
DIST5 = np.array([-0.2, 0.08, -0.0012, 0.0009, -0.01])
DIST8 = np.array([0.15, -0.05, 0.002, -0.001, 0.01, 0.3, -0.02, 0.005])


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def random_c2w(rng: np.random.Generator) -> np.ndarray:
    c2w = np.eye(4)
    c2w[:3, :3] = random_rotation(rng)
    c2w[:3, 3] = rng.normal(size=3) * 2
    return c2w


def make_camera(dist=None, seed=0) -> Camera:
    # An off-centre principal point and non-square pixels catch swapped x/y or fx/fy mistakes.
    rng = np.random.default_rng(seed)
    return Camera(64, 48, 70.0, 66.0, 33.7, 22.9, random_c2w(rng), dist)




# ---- focal / fov ----------------------------------------------------------------------------


def test_fov_focal_known_values_and_round_trip():
    assert fov_to_focal(90.0, 100) == pytest.approx(50.0)
    assert focal_to_fov(50.0, 100) == pytest.approx(90.0)
    for fov in (10.0, 50.0, 120.0):
        assert focal_to_fov(fov_to_focal(fov, 640), 640) == pytest.approx(fov)
    with pytest.raises(ValueError):
        fov_to_focal(180.0, 100)


def test_from_fov_axes():
    c2w = np.eye(4)
    cx = Camera.from_fov(200, 100, 60.0, c2w, axis="x")
    cy = Camera.from_fov(200, 100, 60.0, c2w, axis="y")
    cmin = Camera.from_fov(200, 100, 60.0, c2w, axis="min")
    assert cx.fov_x_deg == pytest.approx(60.0) and cx.fx == cx.fy
    assert cy.fov_y_deg == pytest.approx(60.0)
    assert cmin.fov_y_deg == pytest.approx(60.0)  # height is the smaller side
    assert (cx.cx, cx.cy) == (100.0, 50.0)
    with pytest.raises(ValueError):
        Camera.from_fov(200, 100, 60.0, c2w, axis="z")


def test_from_nerf_known_camera_angle_x():
    # NeRF synthetic (Blender lego): camera_angle_x 0.6911112070083618 at 800 px -> focal 1111.111.
    tm = np.eye(4)
    cam = Camera.from_nerf(tm, 0.6911112070083618, 800, 800)
    assert cam.fx == pytest.approx(1111.1110311937682, rel=1e-9)
    assert cam.fy == cam.fx and (cam.cx, cam.cy) == (400.0, 400.0)
    # An identity OpenGL pose looks down -Z with +Y up.
    np.testing.assert_allclose(cam.forward, [0, 0, -1])
    np.testing.assert_allclose(cam.up, [0, 1, 0])


# ---- pose conventions ----------------------------------------------------------------------


def test_opengl_opencv_round_trip_and_axes():
    rng = np.random.default_rng(1)
    c2w = random_c2w(rng)
    np.testing.assert_allclose(opengl_to_opencv_c2w(opencv_to_opengl_c2w(c2w)), c2w, atol=1e-12)
    gl = opencv_to_opengl_c2w(c2w)
    # Same centre and right axis; OpenGL's y is image up and its z points backward.
    np.testing.assert_allclose(gl[:3, 3], c2w[:3, 3])
    np.testing.assert_allclose(gl[:3, 0], c2w[:3, 0])
    np.testing.assert_allclose(gl[:3, 1], -c2w[:3, 1])
    np.testing.assert_allclose(gl[:3, 2], -c2w[:3, 2])
    batch = np.stack([c2w, np.eye(4)])
    np.testing.assert_allclose(opengl_to_opencv_c2w(batch)[0], opengl_to_opencv_c2w(c2w))


def test_colmap_round_trip():
    rng = np.random.default_rng(2)
    for _ in range(20):
        c2w = random_c2w(rng)
        qvec, t = c2w_to_colmap(c2w)
        assert qvec[0] >= 0 and np.linalg.norm(qvec) == pytest.approx(1.0)
        np.testing.assert_allclose(colmap_to_c2w(qvec, t), c2w, atol=1e-12)
        # COLMAP's pose maps world to camera: x_cam = R x_world + t sends the centre to 0.
        R = qvec_to_rotmat(qvec)
        np.testing.assert_allclose(R @ c2w[:3, 3] + t, 0, atol=1e-12)
        np.testing.assert_allclose(colmap_to_c2w(R, t), c2w, atol=1e-12)
    # 180-degree rotations exercise the branches of the quaternion extraction where qw is ~0.
    for R in (np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])):
        np.testing.assert_allclose(qvec_to_rotmat(rotmat_to_qvec(R)), R, atol=1e-12)
    np.testing.assert_allclose(rotmat_to_qvec(np.eye(3)), [1, 0, 0, 0])


# ---- look_at and orbits --------------------------------------------------------------------


def test_look_at_centres_target_and_stays_upright():
    eye, target = np.array([2.0, -3.0, 1.5]), np.array([0.1, 0.2, -0.3])
    c2w = look_at(eye, target)
    R = c2w[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    cam = Camera(100, 80, 90.0, 90.0, 50.0, 40.0, c2w)
    xy, depth = cam.project(target)
    np.testing.assert_allclose(xy, [cam.cx, cam.cy], atol=1e-9)
    assert depth == pytest.approx(np.linalg.norm(target - eye))
    # World +Z goes up in the image (smaller y), and the horizon stays level (same x).
    xy_up, _ = cam.project(target + [0, 0, 0.1])
    assert xy_up[1] < cam.cy - 1 and xy_up[0] == pytest.approx(cam.cx, abs=1e-9)
    assert cam.right[2] == pytest.approx(0.0, abs=1e-12)
    assert cam.up[2] > 0


def test_look_at_rejects_degenerate_up():
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 0, 5], [0, 0, 0])
    with pytest.raises(ValueError, match="parallel"):
        look_at([0, 0, 0], [0, 0, 1], up=(0, 0, -2))
    with pytest.raises(ValueError):
        look_at([1, 1, 1], [1, 1, 1])


def test_orbit_conventions():
    d = 3.0
    front = orbit_camera(0.0, 0.0, d, 64, 64, 50.0)
    np.testing.assert_allclose(front.center, [0, -d, 0], atol=1e-12)
    np.testing.assert_allclose(front.forward, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(front.up, [0, 0, 1], atol=1e-12)
    side = orbit_camera(90.0, 0.0, d, 64, 64, 50.0)
    np.testing.assert_allclose(side.center, [d, 0, 0], atol=1e-12)
    # Counter-clockwise seen from above: 45 degrees lies between -Y and +X.
    c45 = orbit_camera(45.0, 0.0, d, 64, 64, 50.0).center
    assert c45[0] > 0 and c45[1] < 0
    high = orbit_camera(30.0, 20.0, d, 64, 64, 50.0, target=(0.5, -0.2, 0.1))
    assert high.center[2] > 0.1
    assert np.linalg.norm(high.center - [0.5, -0.2, 0.1]) == pytest.approx(d)
    elev = math.degrees(math.asin((high.center[2] - 0.1) / d))
    assert elev == pytest.approx(20.0)
    xy, _ = high.project(np.array([0.5, -0.2, 0.1]))
    np.testing.assert_allclose(xy, [32, 32], atol=1e-9)
    assert high.fov_x_deg == pytest.approx(50.0)


def test_orbit_poles_are_defined_and_continuous():
    top = orbit_camera(0.0, 90.0, 2.0, 32, 32, 40.0)
    near_top = orbit_camera(0.0, 89.9, 2.0, 32, 32, 40.0)
    np.testing.assert_allclose(top.forward, [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(top.rotation, near_top.rotation, atol=1e-2)
    bottom = orbit_camera(0.0, -90.0, 2.0, 32, 32, 40.0)
    near_bottom = orbit_camera(0.0, -89.9, 2.0, 32, 32, 40.0)
    np.testing.assert_allclose(bottom.rotation, near_bottom.rotation, atol=1e-2)


def test_orbit_cameras_spacing():
    cams = orbit_cameras(8, 15.0, 2.5, 32, 32, 50.0, start_azimuth_deg=10.0)
    assert len(cams) == 8
    for k, cam in enumerate(cams):
        np.testing.assert_allclose(cam.c2w, orbit_camera(10.0 + 45.0 * k, 15.0, 2.5, 32, 32, 50.0).c2w)
        assert np.linalg.norm(cam.center) == pytest.approx(2.5)


def test_distance_to_cover_sphere_fits_sphere_exactly():
    r, fov = 1.0, 50.0
    dist = distance_to_cover_sphere(r, fov)
    assert dist == pytest.approx(r / math.sin(math.radians(25.0)))
    cam = orbit_camera(0.0, 0.0, dist, 100, 60, fov, axis="min")
    # Points on the sphere's silhouette (seen from the camera) must touch the top and bottom edges.
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(20000, 3))
    pts *= r / np.linalg.norm(pts, axis=1, keepdims=True)
    xy, depth = cam.project(pts)
    assert np.all(depth > 0)
    assert xy[:, 1].min() >= -1e-9 and xy[:, 1].max() <= 60 + 1e-9
    assert xy[:, 1].min() < 0.5 and xy[:, 1].max() > 59.5


# ---- rays, projection, distortion ----------------------------------------------------------


def test_principal_ray_is_forward_and_pixel_rays_layout():
    cam = make_camera()
    o, d = cam.rays_at(np.array([cam.cx, cam.cy]))
    np.testing.assert_allclose(d, cam.forward, atol=1e-12)
    np.testing.assert_allclose(o, cam.center)
    origins, dirs = cam.pixel_rays()
    assert origins.shape == dirs.shape == (48, 64, 3)
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(origins, np.broadcast_to(cam.center, origins.shape))
    # Row j, column i is the pixel centre (i + 0.5, j + 0.5).
    _, d_ij = cam.rays_at(np.array([5 + 0.5, 7 + 0.5]))
    np.testing.assert_allclose(dirs[7, 5], d_ij, atol=1e-12)
    # Moving right in the image moves along the camera's +x.
    assert dirs[0, 1] @ cam.right > dirs[0, 0] @ cam.right


@pytest.mark.parametrize("dist", [None, DIST4, DIST5, DIST8])
def test_project_inverts_rays(dist):
    cam = make_camera(dist)
    rng = np.random.default_rng(4)
    xy = rng.uniform([0, 0], [cam.width, cam.height], size=(500, 2))
    o, d = cam.rays_at(xy)
    t = rng.uniform(0.5, 10.0, size=(500, 1))
    xy2, depth = cam.project(o + t * d)
    np.testing.assert_allclose(xy2, xy, atol=1e-8)
    np.testing.assert_allclose(depth, t[:, 0] * (d @ cam.forward), rtol=1e-10)


@pytest.mark.parametrize("dist", [DIST4, DIST5, DIST8])
def test_project_matches_opencv(dist):
    cam = make_camera(dist)
    rng = np.random.default_rng(5)
    # Points in front of the camera, inside a moderate cone where the lens model is meaningful.
    pc = np.concatenate([rng.uniform(-0.4, 0.4, size=(200, 2)), np.ones((200, 1))], axis=1)
    pc *= rng.uniform(1, 5, size=(200, 1))
    pw = pc @ cam.rotation.T + cam.center
    w2c = cam.w2c
    rvec, _ = cv2.Rodrigues(w2c[:3, :3])
    ref, _ = cv2.projectPoints(pw, rvec, w2c[:3, 3], cam.K, dist)
    xy, _ = cam.project(pw)
    np.testing.assert_allclose(xy, ref[:, 0], atol=1e-8)


@pytest.mark.parametrize("dist", [DIST4, DIST5, DIST8])
def test_undistort_matches_opencv(dist):
    cam = make_camera(dist)
    rng = np.random.default_rng(6)
    xy = rng.uniform([0, 0], [cam.width, cam.height], size=(300, 2))
    # OpenCV's default stops after 5 fixed-point steps; ask it to converge so it is a fair reference.
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(xy.reshape(-1, 1, 2), cam.K, dist, criteria=crit)[:, 0]
    n = np.stack([(xy[:, 0] - cam.cx) / cam.fx, (xy[:, 1] - cam.cy) / cam.fy], axis=-1)
    np.testing.assert_allclose(undistort_normalized(n, dist), ref, atol=1e-9)
    # And the ray direction is that normalized point in the camera frame.
    _, d = cam.rays_at(xy)
    d_cam = d @ cam.rotation
    np.testing.assert_allclose(d_cam[:, :2] / d_cam[:, 2:], ref, atol=1e-9)


def test_plucker_moment():
    cam = make_camera(DIST4)
    pl = cam.plucker()
    assert pl.shape == (48, 64, 6) and pl.dtype == np.float32
    o, d = cam.pixel_rays()
    np.testing.assert_allclose(pl[..., :3], d, atol=1e-6)
    np.testing.assert_allclose(pl[..., 3:], np.cross(o, d), atol=1e-5)
    # The moment is a property of the line, not of the point chosen on it.
    p = o + 3.7 * d
    np.testing.assert_allclose(plucker_rays(p, d), plucker_rays(o, d), atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_camera_from_plucker_inverts_plucker(seed):
    cam = make_camera(seed=seed)
    # A crop that is off-centre, anisotropic and partly outside the photo keeps its rays: its own camera comes back.
    for c in (cam, cam.crop_resize(10.3, -5.7, 27.9, 40.4, 16, 24), orbit_camera(200, 35, 2.4, 64, 64, 50.0)):
        back = camera_from_plucker(c.plucker())
        assert (back.width, back.height) == (c.width, c.height)
        np.testing.assert_allclose([back.fx, back.fy, back.cx, back.cy], [c.fx, c.fy, c.cx, c.cy], rtol=1e-4, atol=1e-3)
        np.testing.assert_allclose(back.c2w, c.c2w, atol=1e-5)


def test_camera_from_plucker_refuses_rays_no_pinhole_makes():
    cam = make_camera()
    with pytest.raises(ValueError, match="pinhole"):
        camera_from_plucker(make_camera(DIST5).plucker())  # a real lens bends the rays
    mixed = cam.plucker().copy()
    mixed[:, 32:] = make_camera(seed=5).plucker()[:, 32:]  # half of the image from another camera
    with pytest.raises(ValueError, match="pinhole"):
        camera_from_plucker(mixed)
    mirrored = cam.plucker()[:, ::-1]
    with pytest.raises(ValueError, match="mirrored|pinhole"):
        camera_from_plucker(mirrored)
    broken = cam.plucker().copy()
    broken[3, 4, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        camera_from_plucker(broken)
    with pytest.raises(ValueError, match="shape"):
        camera_from_plucker(cam.plucker()[0])


# ---- crop / resize -------------------------------------------------------------------------


@pytest.mark.parametrize("dist", [None, DIST5, DIST8])
@pytest.mark.parametrize(
    "crop",
    [
        (0, 0, 64, 48, 64, 48),  # identity
        (16, 8, 32, 32, 64, 64),  # integer, upsampled
        (10.3, 5.7, 27.9, 19.4, 16, 24),  # fractional, off-centre, anisotropic
        (-6.5, 30.25, 40.0, 30.0, 20, 15),  # partly outside the image
    ],
)
def test_crop_resize_keeps_every_ray(dist, crop):
    cam = make_camera(dist)
    x0, y0, cw, ch, ow, oh = crop
    sub = cam.crop_resize(x0, y0, cw, ch, ow, oh)
    assert (sub.width, sub.height) == (ow, oh)
    i, j = np.meshgrid(np.arange(ow) + 0.5, np.arange(oh) + 0.5, indexing="xy")
    full_xy = np.stack([x0 + i * cw / ow, y0 + j * ch / oh], axis=-1)
    o_ref, d_ref = cam.rays_at(full_xy)
    o, d = sub.pixel_rays()
    np.testing.assert_allclose(d, d_ref, atol=1e-5)
    np.testing.assert_allclose(o, o_ref, atol=1e-12)
    # Tighter than the spec: the mapping is exact up to floating point.
    np.testing.assert_allclose(d, d_ref, atol=1e-10)


def test_scaled_and_resized_keep_rays():
    cam = make_camera(DIST4)
    half = cam.scaled(0.5)
    assert (half.width, half.height) == (32, 24)
    assert half.fov_x_deg == pytest.approx(cam.fov_x_deg)
    # Each half-resolution pixel covers 2x2 full pixels; its centre is their shared corner.
    _, d = half.rays_at(np.array([3.5, 2.5]))
    _, d_ref = cam.rays_at(np.array([7.0, 5.0]))
    np.testing.assert_allclose(d, d_ref, atol=1e-12)
    odd = cam.resized(50, 30)  # aspect change: fx and fy scale differently
    assert odd.fx == pytest.approx(cam.fx * 50 / 64) and odd.fy == pytest.approx(cam.fy * 30 / 48)


# ---- the dataclass -------------------------------------------------------------------------


def test_derived_quantities_and_with_pose():
    cam = make_camera()
    np.testing.assert_allclose(cam.w2c @ cam.c2w, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(cam.K, [[70, 0, 33.7], [0, 66, 22.9], [0, 0, 1]])
    np.testing.assert_allclose(cam.rotation[:, 2], cam.forward)
    fov_x = math.degrees(math.atan(33.7 / 70) + math.atan((64 - 33.7) / 70))
    assert cam.fov_x_deg == pytest.approx(fov_x)
    moved = cam.with_pose(np.eye(4))
    np.testing.assert_allclose(moved.center, 0)
    assert (moved.fx, moved.cy, moved.width) == (cam.fx, cam.cy, cam.width)
    # Frozen: derive, never mutate.
    with pytest.raises(Exception):
        cam.fx = 1.0  # type: ignore[misc]


def test_moved_by_a_similarity_sees_every_moved_point_where_it_was():
    cam = make_camera()
    angle = 0.7
    similarity = np.eye(4)
    similarity[:3, :3] = 2.5 * np.array([[math.cos(angle), -math.sin(angle), 0], [math.sin(angle), math.cos(angle), 0], [0, 0, 1]])
    similarity[:3, 3] = (0.3, -1.2, 0.4)
    moved = cam.moved_by(similarity)
    points = cam.center + cam.forward * 3.0 + np.random.default_rng(0).uniform(-0.5, 0.5, (20, 3))
    before, depth = cam.project(points)
    after, moved_depth = moved.project(points @ similarity[:3, :3].T + similarity[:3, 3])
    np.testing.assert_allclose(after, before, atol=1e-9)
    np.testing.assert_allclose(moved_depth, 2.5 * depth, atol=1e-9)  # the scale moves centres, not the image
    np.testing.assert_allclose(moved.rotation.T @ moved.rotation, np.eye(3), atol=1e-12)


def test_validation():
    with pytest.raises(ValueError, match="rigid"):
        Camera(10, 10, 5, 5, 5, 5, np.diag([2.0, 2, 2, 1]))
    with pytest.raises(ValueError, match="rigid"):
        Camera(10, 10, 5, 5, 5, 5, np.diag([1.0, 1, -1, 1]))  # a reflection
    with pytest.raises(ValueError, match="distortion"):
        Camera(10, 10, 5, 5, 5, 5, np.eye(4), [0.1, 0.2, 0.3])
    with pytest.raises(ValueError):
        Camera(0, 10, 5, 5, 5, 5, np.eye(4))
    with pytest.raises(ValueError):
        Camera(10, 10, -5, 5, 5, 5, np.eye(4))
    assert Camera(10, 10, 5, 5, 5, 5, np.eye(4), np.zeros(5)).distortion is None


@pytest.mark.parametrize("dist", [None, DIST4, DIST5, DIST8])
def test_dict_round_trip(dist):
    cam = make_camera(dist)
    d = json.loads(json.dumps(cam.to_dict()))
    assert {"w", "h", "fl_x", "fl_y", "cx", "cy", "k1", "k2", "p1", "p2", "transform_matrix"} <= d.keys()
    back = Camera.from_dict(d)
    assert back.allclose(cam, atol=1e-12)
    # transform_matrix is nerfstudio's OpenGL camera-to-world.
    np.testing.assert_allclose(np.array(d["transform_matrix"])[:3, 2], -cam.forward)
    np.testing.assert_allclose(np.array(d["transform_matrix"])[:3, 3], cam.center)


def test_from_dict_nerf_style_and_unsupported():
    frame = {"transform_matrix": np.eye(4).tolist()}
    shared = {"w": 800, "h": 600, "camera_angle_x": 0.6911112070083618}
    cam = Camera.from_dict({**shared, **frame})
    assert cam.fx == pytest.approx(1111.1110311937682) and cam.fy == cam.fx
    assert (cam.cx, cam.cy) == (400.0, 300.0) and cam.distortion is None
    with pytest.raises(ValueError, match="not supported"):
        Camera.from_dict({**shared, **frame, "camera_model": "OPENCV_FISHEYE"})
    with pytest.raises(ValueError, match="k4"):
        Camera.from_dict({**shared, **frame, "k4": 0.1})
    with pytest.raises(ValueError, match="lacks"):
        Camera.from_dict(frame)


def test_nearest_cameras_are_the_closest_centres_other_than_its_own():
    ring = {f"{k:04d}": orbit_camera(36.0 * k, 20.0, 3.0, 64, 64, 40.0) for k in range(10)}
    assert sorted(nearest_cameras(ring, "0000", 2)) == ["0001", "0009"]
    assert set(nearest_cameras(ring, "0000", 4)) == {"0001", "0009", "0002", "0008"}
    assert "0000" not in nearest_cameras(ring, "0000", 10) and len(nearest_cameras(ring, "0000", 10)) == 9
    by_index = dict(enumerate(ring.values()))  # any keys: photo carving numbers its views
    assert sorted(nearest_cameras(by_index, 5, 2)) == [4, 6]
