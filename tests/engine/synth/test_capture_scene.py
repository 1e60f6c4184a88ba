"""The synthetic photo shoot's set: the object is lit by the environment and by the ground it stands on."""

from __future__ import annotations

import numpy as np

from lirm.engine.synth.capture_scene import environment_around_object
from lirm.renderer.material import PBRMaterial
from lirm.renderer.primitives import quad
from lirm.renderer.procedural_environments import make_procedural_environment

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _grey_floor(albedo: float, z: float, size: float):
    floor = quad(size=size, material=PBRMaterial(base_color_factor=(albedo, albedo, albedo, 1.0),
                                                  metallic_factor=0.0, roughness_factor=1.0))
    floor.positions[:, 2] = z
    return floor


def test_the_object_sees_the_lit_floor_below_and_the_environment_elsewhere(renderer):
    environment = make_procedural_environment("overcast", width=256)
    around = environment_around_object(renderer, environment, _grey_floor(0.5, -0.5, 8.0), face_size=128)
    directions, solid_angle = environment.texel_directions()
    assert around.radiance.shape == environment.radiance.shape
    above = directions[..., 2] > 0.0
    np.testing.assert_array_equal(around.radiance[above], environment.radiance[above])
    # Straight down: the floor's own radiance, a grey diffuser under the sky: albedo x irradiance / pi
    # (plus a few per cent of specular at F0 0.04).
    up = np.clip(directions[..., 2], 0.0, None)
    irradiance = (environment.radiance * (up * solid_angle)[..., None]).sum((0, 1))
    nadir = around.radiance[-1].mean(0)
    np.testing.assert_allclose(nadir, 0.5 * irradiance / np.pi, rtol=0.1)
    # Just below the horizon, past the floor's corners (5.7 units away), the environment shows again.
    grazing = (directions[..., 2] < 0.0) & (directions[..., 2] > -0.06)
    np.testing.assert_allclose(around.radiance[grazing], environment.radiance[grazing])
    # The floor is a brighter "ground" than the overcast sky's own: the object gets more light from below.
    below = directions[..., 2] < -0.2
    assert (around.radiance[below] @ LUMINANCE).mean() > 1.2 * (environment.radiance[below] @ LUMINANCE).mean()
