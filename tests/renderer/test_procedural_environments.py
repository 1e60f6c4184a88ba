"""Built-in procedural environments: exposure, geometry conventions and determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lirm.renderer.environment import Environment, direction_to_equirect_uv
from lirm.renderer.procedural_environments import (
    PROCEDURAL_ENVIRONMENTS,
    OvercastConfig,
    SkyConfig,
    StudioConfig,
    make_procedural_environment,
    random_procedural_environment,
)

LUM = np.array([0.2126, 0.7152, 0.0722])
NAMES = list(PROCEDURAL_ENVIRONMENTS)


def up_irradiance_over_pi(env: Environment) -> float:
    """Independent of the module: what a white up-facing Lambertian surface sees (luminance)."""
    dirs, solid_angle = env.texel_directions()
    weight = np.maximum(dirs[..., 2], 0.0) * solid_angle
    e = (env.radiance.astype(np.float64) * weight[..., None]).sum(axis=(0, 1))
    return float(e @ LUM) / np.pi


def unit(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def brightest_direction(env: Environment) -> np.ndarray:
    lum = env.radiance @ LUM
    row, col = np.unravel_index(np.argmax(lum), lum.shape)
    return env.texel_directions()[0][row, col]


@pytest.fixture(scope="module")
def presets() -> dict[str, Environment]:
    return {n: make_procedural_environment(n, width=1024) for n in NAMES}


@pytest.mark.parametrize("name", NAMES)
def test_preset_is_finite_nonnegative_2to1_and_exposed_to_one(presets, name):
    env = presets[name]
    assert env.radiance.shape == (512, 1024, 3)
    assert env.radiance.dtype == np.float32
    assert np.isfinite(env.radiance).all() and env.radiance.min() >= 0.0
    assert env.name == name
    assert up_irradiance_over_pi(env) == pytest.approx(1.0, rel=5e-3)


@pytest.mark.parametrize("name", NAMES)
def test_any_width_gives_height_half_and_same_exposure(name):
    env = make_procedural_environment(name, width=96)
    assert env.radiance.shape == (48, 96, 3)
    assert up_irradiance_over_pi(env) == pytest.approx(1.0, rel=5e-3)


def test_unknown_name_lists_the_valid_ones():
    with pytest.raises(ValueError, match="studio, sky, overcast"):
        make_procedural_environment("beach")
    with pytest.raises(ValueError):
        make_procedural_environment("sky", width=3)


@pytest.mark.parametrize("azimuth, elevation", [(120.0, 35.0), (-40.0, 8.0), (250.0, 62.0), (0.0, 20.0)])
def test_sun_is_where_its_azimuth_and_elevation_say(azimuth, elevation):
    config = SkyConfig(sun_azimuth_deg=azimuth, sun_elevation_deg=elevation)
    env = config.render(1024)
    sun = unit(azimuth, elevation)
    assert angle_deg(brightest_direction(env), sun) < 2.0
    # The same place through the one uv convention: column from u, row from v.
    u, v = direction_to_equirect_uv(sun)
    lum = env.radiance @ LUM
    row, col = np.unravel_index(np.argmax(lum), lum.shape)
    texel_deg = 180.0 / env.height
    dcol = min(abs(col + 0.5 - u * env.width), env.width - abs(col + 0.5 - u * env.width))
    assert dcol * texel_deg * np.cos(np.radians(elevation)) < 2.0
    assert abs(row + 0.5 - v * env.height) * texel_deg < 2.0


def test_azimuth_90_turns_toward_plus_y_which_is_left_of_centre():
    env = SkyConfig(sun_azimuth_deg=90.0, sun_elevation_deg=30.0).render(512)
    lum = env.radiance @ LUM
    _, col = np.unravel_index(np.argmax(lum), lum.shape)
    assert abs((col + 0.5) / env.width - 0.25) < 0.01
    assert brightest_direction(env)[1] > 0.8


def test_sun_disc_has_a_1_5_degree_radius_and_soft_edge(presets):
    env = presets["sky"]
    sun = SkyConfig().sun_direction
    side = np.cross(sun, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)

    def at(deg):
        d = np.cos(np.radians(deg)) * sun + np.sin(np.radians(deg)) * side
        return float(env.lookup(d) @ LUM)

    centre = at(0.0)
    assert at(1.0) > 0.4 * centre  # inside the disc (limb darkened, still bright)
    assert at(3.0) < 0.01 * centre  # sky, not sun
    # The edge is a ramp over a few texels, not a step from disc to sky.
    ramp = [at(d) for d in np.linspace(1.2, 1.9, 8)]
    assert all(a >= b for a, b in zip(ramp, ramp[1:]))
    assert sum(0.01 * centre < r < 0.4 * centre for r in ramp) >= 2


def test_sky_is_bluer_at_zenith_than_at_horizon_and_ground_is_darker(presets):
    env = presets["sky"]
    away_from_sun = SkyConfig().sun_azimuth_deg + 180.0
    zenith = env.lookup(np.array([0.0, 0.0, 1.0]))
    horizon = env.lookup(unit(away_from_sun, 2.0))
    ground = env.lookup(unit(away_from_sun, -20.0))

    def blueness(c):
        return c[2] / c.sum()

    assert blueness(zenith) > blueness(horizon) + 0.05
    assert ground @ LUM < 0.5 * (horizon @ LUM)
    upper, lower = env.radiance[: env.height // 2] @ LUM, env.radiance[env.height // 2 :] @ LUM
    assert np.median(lower) < np.median(upper)


def test_overcast_follows_cie_in_the_upper_hemisphere(presets):
    env = presets["overcast"]
    dirs, _ = env.texel_directions()
    lum = env.radiance.astype(np.float64) @ LUM
    upper = dirs[..., 2] > 0.0
    model = (1.0 + 2.0 * dirs[..., 2]) / 3.0
    ratio = lum[upper] / model[upper]
    assert np.ptp(ratio) / ratio.mean() < 1e-4
    # Zenith three times the horizon; E/pi = 1 fixes the zenith at 9/7 (the CIE integral is 7/9).
    assert ratio.mean() == pytest.approx(9.0 / 7.0, rel=5e-3)
    ground = lum[dirs[..., 2] < 0.0]
    assert np.ptp(ground) < 1e-5 and ground.mean() < lum[upper].min()


def test_studio_is_brightest_in_its_box_directions(presets):
    env = presets["studio"]
    config = PROCEDURAL_ENVIRONMENTS["studio"]
    lum = env.radiance @ LUM
    median = float(np.median(lum))
    centres = [unit(b.azimuth_deg, b.elevation_deg) for b in config.boxes]
    for box, centre in zip(config.boxes, centres):
        assert float(env.lookup(centre) @ LUM) > 20.0 * median, box
    # The brightest texel lies inside one of the boxes.
    peak = brightest_direction(env)
    assert any(
        angle_deg(peak, c) < 0.5 * np.hypot(b.width_deg, b.height_deg) for b, c in zip(config.boxes, centres)
    )
    # Away from the boxes it is dark: most of the panorama is well under a tenth of the key.
    key = float(env.lookup(centres[0]) @ LUM)
    assert np.mean(lum < 0.05 * key) > 0.8


def test_studio_floor_is_slightly_brighter_than_the_walls():
    env = dataclasses.replace(PROCEDURAL_ENVIRONMENTS["studio"], boxes=()).render(256)
    lum = env.radiance @ LUM
    walls, floor = lum[: env.height // 2 - 8].mean(), lum[env.height // 2 + 8 :].mean()
    assert walls < floor < 4.0 * walls


@pytest.mark.parametrize("name", NAMES)
def test_randomized_is_deterministic_by_seed_and_differs_across_seeds(name):
    base = PROCEDURAL_ENVIRONMENTS[name]
    a = base.randomized(np.random.default_rng(7))
    b = base.randomized(np.random.default_rng(7))
    c = base.randomized(np.random.default_rng(8))
    assert a == b and a != c and type(a) is type(base)
    ea, eb, ec = (x.render(128) for x in (a, b, c))
    np.testing.assert_array_equal(ea.radiance, eb.radiance)
    assert not np.allclose(ea.radiance, ec.radiance)
    for env in (ea, ec):
        assert np.isfinite(env.radiance).all() and env.radiance.min() >= 0.0
        assert up_irradiance_over_pi(env) == pytest.approx(1.0, rel=5e-3)


def test_random_procedural_environment_is_deterministic_and_varied():
    first = [random_procedural_environment(np.random.default_rng(s), width=64).radiance for s in range(6)]
    again = [random_procedural_environment(np.random.default_rng(s), width=64).radiance for s in range(6)]
    for x, y in zip(first, again):
        np.testing.assert_array_equal(x, y)
    assert len({x.tobytes() for x in first}) == 6
    with pytest.raises(ValueError, match="valid names"):
        random_procedural_environment(np.random.default_rng(0), names=("moon",))


def test_configs_reject_nonsense():
    with pytest.raises(ValueError):
        SkyConfig(sun_elevation_deg=120.0)
    with pytest.raises(ValueError):
        OvercastConfig(sky_color=(1.0, -1.0, 1.0))
    with pytest.raises(ValueError):
        dataclasses.replace(StudioConfig().boxes[0], width_deg=0.0)
