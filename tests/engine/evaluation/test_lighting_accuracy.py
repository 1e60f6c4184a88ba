"""The lighting bench's figures: the brightest light's direction, the up-plane irradiance, where that
irradiance comes from by elevation, and its colour."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.evaluation.lighting_accuracy import (ELEVATION_BANDS, LUMINANCE, chromaticity, compare_lighting,
                                                      up_irradiance, up_irradiance_by_elevation)
from lirm.renderer.environment import Environment
from lirm.renderer.procedural_environments import SkyConfig


def test_a_uniform_sky_splits_over_the_bands_as_the_cosine_integral_says():
    environment = Environment(np.ones((128, 256, 3), np.float32), "white")
    bands = up_irradiance_by_elevation(environment)
    # A band of unit radiance sends pi (sin^2 top - sin^2 bottom) onto an upward-facing plane.
    expected = [np.pi * (np.sin(np.radians(hi)) ** 2 - np.sin(np.radians(lo)) ** 2) for lo, hi in ELEVATION_BANDS]
    # (Each texel counts whole in the band of its centre: 1.4-degree rows blur the edges by a few per cent.)
    np.testing.assert_allclose(bands, expected, rtol=0.05)
    assert bands.sum() == pytest.approx(float(up_irradiance(environment) @ LUMINANCE), rel=1e-6)


@pytest.mark.parametrize("elevation, band", [(45.0, 2), (18.0, 1)])
def test_a_sun_lights_the_plane_from_its_own_band(elevation, band):
    environment = SkyConfig(sun_azimuth_deg=30.0, sun_elevation_deg=elevation).render(512)
    bands = up_irradiance_by_elevation(environment)
    assert np.argmax(bands) == band and bands[band] > 0.5 * bands.sum(), bands


def test_the_colour_of_a_blue_sky_is_blue_and_sums_to_one():
    sky = np.zeros((64, 128, 3), np.float32)
    sky[:32] = (0.2, 0.3, 0.6)  # the upper half blue
    sky[32:] = (0.5, 0.4, 0.3)  # the ground warm
    shares = chromaticity(up_irradiance(Environment(sky, "blue sky")))
    assert shares.sum() == pytest.approx(1.0) and np.argmax(shares) == 2
    np.testing.assert_allclose(shares, np.array([0.2, 0.3, 0.6]) / 1.1, atol=1e-3)


def test_an_environment_compared_with_itself_agrees_everywhere():
    environment = SkyConfig(sun_azimuth_deg=100.0, sun_elevation_deg=30.0).render(256)
    accuracy = compare_lighting(environment, environment, np.eye(3))
    assert accuracy.brightest_angle_deg < 1e-3 and accuracy.up_irradiance_ratio == pytest.approx(1.0)
    np.testing.assert_allclose(accuracy.estimated_by_elevation, accuracy.true_by_elevation)
    assert accuracy.meets_goal()
