"""Crops keep each pixel's full-image ray and the image content they cut out."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at
from lirm.engine.capture.crop import CropConfig, EmptyMaskError, crop_box_for_mask, prepare_view


def _scene(w=640, h=480, distortion=None):
    camera = Camera(width=w, height=h, fx=520.0, fy=515.0, cx=331.3, cy=236.8,
                    c2w=look_at((0.3, -3.0, 1.2), (0, 0, 0)), distortion=distortion)
    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    mask = np.zeros((h, w), np.uint8)
    mask[300:380, 420:470] = 255  # a small object off-centre
    return camera, image, mask


@pytest.mark.parametrize("distortion", [None, np.array([-0.12, 0.03, 0.001, -0.0005])])
@pytest.mark.parametrize("size", [64, 256])
def test_crop_rays_equal_the_full_image_rays(distortion, size):
    camera, image, mask = _scene(distortion=distortion)
    view = prepare_view("0001", image, mask, camera, CropConfig(size=size))
    x0, y0, side = view.crop_box
    i = np.arange(size) + 0.5
    xs, ys = np.meshgrid(x0 + i * side / size, y0 + i * side / size)
    origins, dirs = camera.rays_at(np.stack([xs, ys], -1))
    moment = np.cross(origins, dirs)
    np.testing.assert_allclose(view.plucker[..., :3], dirs, atol=1e-5)
    np.testing.assert_allclose(view.plucker[..., 3:], moment, atol=1e-5)


def test_crop_box_is_a_square_around_the_mask_with_margin():
    _, _, mask = _scene()
    x0, y0, side = crop_box_for_mask(mask, margin=0.1)
    assert side == int(np.ceil(80 * 1.2))
    assert x0 <= 420 and x0 + side >= 470 and y0 <= 300 and y0 + side >= 380
    assert abs((x0 + side / 2) - 445) <= 1 and abs((y0 + side / 2) - 340) <= 1


def test_a_crop_without_resampling_is_the_sub_image_exactly():
    camera, image, mask = _scene()
    x0, y0, side = crop_box_for_mask(mask, margin=0.1)
    view = prepare_view("0001", image, mask, camera, CropConfig(size=side, margin=0.1))
    np.testing.assert_array_equal(np.round(view.image_bg * 255).astype(np.uint8), image[y0:y0 + side, x0:x0 + side])
    inside = view.mask > 0.999
    np.testing.assert_allclose(view.image_masked[inside], view.image_bg[inside])
    np.testing.assert_allclose(view.image_masked[view.mask < 1e-6], 1.0)  # white outside the object


def test_a_projected_point_lands_on_the_same_content_in_the_crop():
    camera, image, mask = _scene()
    point = camera.rays_at(np.array([[445.5, 340.5]]))
    world = point[0][0] + point[1][0] * 2.7
    image[335:346, 440:451] = (255, 0, 0)  # a red dot around that pixel
    view = prepare_view("0001", image, mask, camera, CropConfig(size=128))
    (u, v), _ = view.camera.project(world)
    np.testing.assert_allclose(view.image_bg[int(v), int(u)], [1.0, 0.0, 0.0], atol=0.05)


def test_crops_reaching_outside_the_image_are_padded_and_keep_rays():
    camera, image, mask = _scene()
    mask[:] = 0
    mask[0:60, 600:640] = 255  # object cut by the top-right corner
    view = prepare_view("0001", image, mask, camera, CropConfig(size=64))
    x0, y0, side = view.crop_box
    assert y0 < 0 and x0 + side > 640
    assert view.image_bg[0, -1].max() == 0.0 and view.mask[0, -1] == 0.0
    assert np.isfinite(view.plucker).all()


def test_empty_mask_is_refused():
    camera, image, mask = _scene()
    with pytest.raises(EmptyMaskError):
        prepare_view("0001", image, np.zeros_like(mask), camera)
