"""The lighting a capture was photographed in, from its photos' backgrounds."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at
from lirm.engine.lighting.camera_response import display_to_radiance
from lirm.engine.lighting.capture_lighting import (CaptureLightingConfig, estimate_capture_lighting, lighting_picture,
                                                   push_pull_fill)
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.primitives import uv_sphere
from lirm.renderer.procedural_environments import make_procedural_environment
from lirm.renderer.tonemap import tonemap


def test_the_camera_response_inverts_the_display_transform():
    rng = np.random.default_rng(0)
    # Natural colours (a saturated primary leaves the display gamut and cannot be inverted exactly).
    radiance = rng.uniform(0.02, 0.6, (500, 1)) * rng.uniform(0.7, 1.0, (500, 3))
    np.testing.assert_allclose(display_to_radiance(tonemap(radiance)), radiance, atol=2e-3)
    np.testing.assert_allclose(display_to_radiance(tonemap(radiance, tonemapper="linear"), "srgb"), radiance, atol=1e-9)
    assert np.all(display_to_radiance(np.ones(3)) > 10.0)  # a clipped white is a (large) lower bound, not 1


def test_push_pull_keeps_what_is_known_and_fills_the_rest_between_its_values():
    rng = np.random.default_rng(0)
    values = rng.uniform(0.2, 0.8, (32, 64, 3))
    known = np.zeros((32, 64), bool)
    known[16:] = True  # the lower hemisphere seen, the upper not
    known[20:24, 10:20] = False  # and a hole inside it
    filled = push_pull_fill(values, known)
    np.testing.assert_array_equal(filled[known], values[known])
    assert filled[~known].min() >= 0.2 - 1e-9 and filled[~known].max() <= 0.8 + 1e-9
    assert np.abs(filled[:, 0] - filled[:, -1]).mean() < 0.1  # continuous across the longitude seam


@pytest.fixture(scope="module")
def photographed(renderer):
    """A grey sphere photographed from a ring of 8 cameras with the environment as its backdrop."""
    environment = make_procedural_environment("studio", width=256)
    lighting = renderer.prepare_lighting(environment)
    scene = renderer.upload([uv_sphere(0.5, material=PBRMaterial(base_color_factor=(0.5, 0.5, 0.5, 1.0)))])
    cameras, images, masks = {}, {}, {}
    try:
        for i in range(8):
            angle = 2 * np.pi * i / 8
            eye = (3.0 * np.cos(angle), 3.0 * np.sin(angle), 1.2)
            camera = Camera.from_fov(160, 120, 60.0, look_at(eye, (0, 0, 0)))
            out = renderer.render_view(scene, camera, lighting, RenderSettings())
            cameras[f"{i:04d}"] = camera
            images[f"{i:04d}"] = np.round(out.beauty * 255).astype(np.uint8)
            masks[f"{i:04d}"] = np.where(out.mask > 0.5, 255, 0).astype(np.uint8)
    finally:
        scene.release()
        lighting.maps.release()
    return environment, cameras, images, masks


def test_the_seen_directions_hold_the_environment_they_saw(photographed):
    environment, cameras, images, masks = photographed
    # A backdrop at infinity: a large proxy sphere puts every background pixel at its own direction.
    config = CaptureLightingConfig(width=64, proxy_radius=200.0)
    estimate = estimate_capture_lighting(images, masks, cameras, config)
    assert estimate.photos_used == 8 and 0.3 < estimate.seen_fraction < 0.9
    seen = (estimate.observed >= 4) & (estimate.clipped == 0)
    truth = Environment(environment.radiance, "truth").lookup(estimate.environment.texel_directions()[0])
    # The truth point-sampled at texel centres against photo pixels averaged over the texel.
    error = np.abs(estimate.environment.radiance[seen] - truth[seen]).mean() / truth[seen].mean()
    assert error < 0.15
    picture = lighting_picture(estimate)
    assert picture.dtype == np.uint8 and picture.shape == (32 * 4, 64 * 4, 3)


def test_clipped_pixels_are_flagged_and_taken_as_a_lower_bound(photographed):
    _, cameras, images, masks = photographed
    burnt = {f: np.full_like(image, 255) for f, image in images.items()}
    estimate = estimate_capture_lighting(burnt, masks, cameras, CaptureLightingConfig(width=32))
    seen = estimate.observed > 0
    assert estimate.clipped[seen].min() == 1.0 and estimate.clipped_fraction == 1.0
    assert estimate.environment.radiance[seen].min() > 10.0


def test_photos_without_background_have_no_lighting(photographed):
    _, cameras, images, masks = photographed
    cut_out = {f: np.dstack([image, masks[f]]) for f, image in images.items()}  # transparent around the object
    with pytest.raises(ValueError, match="no photo shows any background"):
        estimate_capture_lighting(cut_out, masks, cameras)


def test_a_floor_in_the_photos_lands_where_the_object_sees_it(renderer):
    """A grey sphere on a pebbled floor: with the capture's support plane as the proxy, the floor's
    pixels land in the directions the object sees it in; on the sphere alone they land too high."""
    from lirm.engine.synth.capture_scene import environment_around_object, ground_plane

    environment = make_procedural_environment("overcast", width=256)
    floor = ground_plane(10.0, -0.5, seed=0, texture_size=512)
    around = environment_around_object(renderer, environment, floor, face_size=256)  # what the sphere sees
    lighting = renderer.prepare_lighting(around)
    scene = renderer.upload([uv_sphere(0.5, material=PBRMaterial(base_color_factor=(0.5, 0.5, 0.5, 1.0))), floor])
    sphere_only = renderer.upload([uv_sphere(0.5)])
    cameras, images, masks = {}, {}, {}
    try:
        for i in range(8):
            angle = 2 * np.pi * i / 8
            camera = Camera.from_fov(160, 120, 60.0, look_at((3.0 * np.cos(angle), 3.0 * np.sin(angle), 1.5), (0, 0, 0)))
            cameras[f"{i:04d}"] = camera
            images[f"{i:04d}"] = np.round(renderer.render_view(scene, camera, lighting, RenderSettings()).beauty * 255).astype(np.uint8)
            masks[f"{i:04d}"] = np.where(renderer.render_view(sphere_only, camera, lighting, RenderSettings()).mask > 0.5, 255, 0).astype(np.uint8)
    finally:
        scene.release()
        sphere_only.release()
        lighting.maps.release()
    config = CaptureLightingConfig(width=64)
    on_plane = estimate_capture_lighting(images, masks, cameras, config, support_plane=(np.array([0.0, 0.0, 1.0]), -0.5))
    on_sphere = estimate_capture_lighting(images, masks, cameras, config)
    assert on_plane.on_support_plane and not on_sphere.on_support_plane
    directions = on_plane.environment.texel_directions()[0]
    truth = around.lookup(directions)

    def floor_error(estimate):
        # Texels well below the horizon that the photos saw: the floor as the object sees it.
        seen = (estimate.observed >= 4) & (estimate.clipped == 0) & (directions[..., 2] < -0.15)
        return seen.sum(), np.abs(estimate.environment.radiance[seen] - truth[seen]).mean() / truth[seen].mean()

    seen_on_plane, error_on_plane = floor_error(on_plane)
    _, error_on_sphere = floor_error(on_sphere)
    assert seen_on_plane > 50
    assert error_on_plane < 0.25 and error_on_plane < 0.7 * error_on_sphere
