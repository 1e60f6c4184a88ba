"""The viewport's raw-field channel: the camera is carried into the capture's frame correctly, and the
worker renders the field of the update being looked at."""

from __future__ import annotations

import shutil
import time

import numpy as np

from lirm.app.field_preview import FieldPreview, camera_in_capture_frame
from lirm.engine.cameras import orbit_camera


def test_camera_moves_into_the_capture_frame():
    world_from_capture = np.diag([0.25, 0.25, 0.25, 1.0])
    world_from_capture[:3, 3] = [0.1, -0.2, 0.3]
    camera = orbit_camera(40, 25, 0.8, 64, 48, 40.0, target=(0.1, -0.2, 0.3))
    inside = camera_in_capture_frame(camera, world_from_capture)
    points = np.random.default_rng(0).uniform(-1, 1, (20, 3))  # capture frame
    world = (np.c_[points, np.ones(20)] @ world_from_capture.T)[:, :3]
    a, za = camera.project(world)
    b, zb = inside.project(points)
    np.testing.assert_allclose(a, b, atol=1e-6)
    np.testing.assert_allclose(za * 4.0, zb, rtol=1e-9)


def test_the_field_of_an_update_renders_in_the_background(lego_capture, tmp_path):
    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.cli import main
    from lirm.engine.export.capture_export import export_transform

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "1", "--novel-views", "1", "--render-size", "16",
                 "--grid-resolution", "32"]) == 0
    transform = export_transform(Capture.open(capture))
    scale = float(np.cbrt(np.linalg.det(transform[:3, :3])))
    camera = orbit_camera(30, 20, 3.0 * scale, 64, 48, 40.0, target=transform[:3, 3])
    preview = FieldPreview(size=32, samples_per_ray=24)
    preview.request(capture, 1, None, camera, transform)
    deadline = time.time() + 120
    while preview.busy() and time.time() < deadline:
        time.sleep(0.1)
    assert preview.error is None
    assert preview.image.shape == (24, 32, 3) and np.isfinite(preview.image).all()
    assert preview.image.std() > 0.01  # something in front of the white background
