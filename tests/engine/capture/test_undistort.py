"""Undistorted views put every world point where the pinhole camera projects it."""

from __future__ import annotations

import numpy as np

from lirm.engine.cameras import Camera, look_at
from lirm.engine.capture.undistort import undistort_image


def test_a_point_moves_to_its_pinhole_projection():
    camera = Camera(width=320, height=240, fx=260.0, fy=258.0, cx=161.0, cy=119.0,
                    c2w=look_at((0, -3, 0.5), (0, 0, 0)), distortion=np.array([-0.25, 0.08, 0.002, -0.001]))
    world = np.array([0.9, 0.3, 0.6])  # lands near a corner, where distortion is strongest
    (u, v), _ = camera.project(world)
    image = np.zeros((240, 320, 3), np.uint8)
    image[int(v) - 2:int(v) + 3, int(u) - 2:int(u) + 3] = 255
    out, pinhole = undistort_image(image, camera)
    assert pinhole.distortion is None
    (pu, pv), _ = pinhole.project(world)
    ys, xs = np.nonzero(out[:, :, 0] > 128)
    np.testing.assert_allclose([xs.mean() + 0.5, ys.mean() + 0.5], [pu, pv], atol=1.0)
    assert abs(pu - u) + abs(pv - v) > 3  # the point really moved


def test_without_distortion_nothing_changes():
    camera = Camera.from_fov(64, 48, 50.0, look_at((0, -3, 0), (0, 0, 0)))
    image = np.random.default_rng(0).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    out, same = undistort_image(image, camera)
    assert out is image and same is camera
