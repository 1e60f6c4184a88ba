"""Synthetic views cut like the capture pipeline cuts photos, and the pixel-scale augmentation."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.capture.crop import CropConfig
from lirm.engine.synth.training_scenes import TrainingSceneConfig, make_training_scene
from lirm.engine.synth.view_crops import crop_like_capture, resize_views, scale_pixels


@pytest.fixture(scope="module")
def scene(renderer):
    return make_training_scene(renderer, 3, TrainingSceneConfig(views=4, size=96, supersample=1, environment_width=128)).views


def test_crop_frames_the_object_with_the_capture_margin(scene):
    cropped = crop_like_capture(scene, 64)
    assert cropped.image.shape == (4, 64, 64, 3) and cropped.normal.shape == (4, 64, 64, 3)
    for i in range(4):
        ys, xs = np.nonzero(cropped.mask[i] > 0.5)
        extent = max(xs.max() - xs.min() + 1, ys.max() - ys.min() + 1)
        # The mask's longer side spans 1 / (1 + 2 margin) of the crop, as capture/crop.py makes it.
        assert extent / 64 == pytest.approx(1 / (1 + 2 * CropConfig().margin), abs=0.06)
        # Off the object the masked image is white.
        assert np.all(cropped.image[i][cropped.mask[i] < 1e-3] > 0.99)


def test_crop_pixels_show_what_their_rays_saw_in_the_full_view(scene):
    cropped = crop_like_capture(scene, 64)
    for i in range(4):
        camera, full = cropped.cameras[i], scene.cameras[i]
        origins, directions = camera.pixel_rays()
        xy, depth = full.project(origins + 3.0 * directions)
        assert np.all(depth > 0)
        px = np.clip(np.floor(xy).astype(int), 0, full.width - 1)
        seen = scene.mask[i][px[..., 1], px[..., 0]]
        sure = (np.abs(cropped.mask[i] - 0.5) > 0.45) & (np.abs(seen - 0.5) > 0.45)
        assert np.mean((cropped.mask[i] > 0.5)[sure] == (seen > 0.5)[sure]) > 0.97


def test_resize_keeps_the_frame(scene):
    resized = resize_views(scene, 48)
    assert resized.image.shape == (4, 48, 48, 3)
    assert resized.cameras[0].fov_x_deg == pytest.approx(scene.cameras[0].fov_x_deg, rel=1e-6)


def test_pixel_scale_brightens_the_photo_but_not_the_white_or_the_materials(scene):
    brighter = scale_pixels(scene, 1.2)
    obj = scene.mask > 0.99
    assert np.all(brighter.image[obj] >= scene.image[obj] - 1e-6)
    assert brighter.image[obj].mean() > scene.image[obj].mean() * 1.05
    np.testing.assert_array_equal(brighter.image[scene.mask < 1e-3], 1.0)
    np.testing.assert_array_equal(brighter.albedo, scene.albedo)
    darker = scale_pixels(scene, 0.8)
    assert darker.image_bg.mean() < scene.image_bg.mean()
