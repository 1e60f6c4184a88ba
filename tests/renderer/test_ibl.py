"""The GPU environment preprocessing against numpy references (runs on llvmpipe in CI)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lirm.renderer.brdf_reference import split_sum_terms
from lirm.renderer.environment import Environment
from lirm.renderer.ibl import sample_cube


def _random_directions(n: int, seed: int = 0) -> np.ndarray:
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _linear_environment(height: int = 128) -> Environment:
    """Radiance (1 + x, 1 + y, 1 + z) of the direction: smooth and different along every axis, so a
    mirrored or rotated convention anywhere shows up as a wrong colour."""
    env = Environment(np.ones((height, 2 * height, 3), np.float32), name="linear")
    dirs, _ = env.texel_directions()
    return Environment((1.0 + dirs).astype(np.float32), name="linear")


def _load_hdr(path) -> Environment:
    bgr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return Environment(np.ascontiguousarray(bgr[:, :, ::-1]), name=path.stem)


@pytest.fixture(scope="module")
def linear_maps(renderer):
    env = _linear_environment()
    maps = renderer.baker.bake(env)
    yield env, maps
    maps.release()


def test_brdf_lut_matches_independent_monte_carlo(renderer):
    lut = np.frombuffer(renderer.baker.brdf_lut.read(), dtype=np.float32).reshape(128, 128, 2)  # [roughness, n.v]
    for n_dot_v, roughness in [(0.5, 0.25), (0.5, 0.5), (0.9, 0.75), (1.0, 1.0), (0.2, 1.0), (0.3, 0.6)]:
        col = min(int(n_dot_v * 128), 127)
        row = min(int(roughness * 128), 127)
        a_ref, b_ref = split_sum_terms((col + 0.5) / 128, (row + 0.5) / 128)
        a, b = lut[row, col]
        assert a == pytest.approx(a_ref, abs=0.01), (n_dot_v, roughness)
        assert b == pytest.approx(b_ref, abs=0.01), (n_dot_v, roughness)


def test_environment_cube_follows_the_equirect_direction_convention(gl_context, linear_maps):
    env, maps = linear_maps
    dirs = _random_directions(500)
    got = sample_cube(gl_context, maps.environment_cube, dirs, lod=0.0)[:, :3]
    np.testing.assert_allclose(got, 1.0 + dirs, atol=0.02)


def test_irradiance_of_a_linear_environment_is_analytic(gl_context, linear_maps):
    # For L(w) = 1 + a.w, (1/pi) * integral of L(w) max(0, n.w) dw = 1 + (2/3) a.n.
    _, maps = linear_maps
    normals = _random_directions(200, seed=1)
    got = sample_cube(gl_context, maps.irradiance_cube, normals)[:, :3]
    np.testing.assert_allclose(got, 1.0 + 2.0 / 3.0 * normals, rtol=0.01)


def _monte_carlo_irradiance(env: Environment, normals: np.ndarray, samples: int, seed: int) -> np.ndarray:
    """(1/pi) E(n) by importance sampling the panorama's texels by radiance x solid angle, with
    directions drawn uniformly inside each chosen texel."""
    rng = np.random.default_rng(seed)
    h, w = env.height, env.width
    _, solid_angle = env.texel_directions()
    luminance = env.radiance @ np.array([0.2126, 0.7152, 0.0722])
    weight = (luminance + luminance.mean() * 0.05) * solid_angle  # floor keeps dark texels reachable
    p = (weight / weight.sum()).ravel()
    idx = rng.choice(p.size, size=samples, p=p)
    row, col = np.divmod(idx, w)
    # Uniform in solid angle within the texel: cos(theta) and phi uniform between the edges.
    cos_hi, cos_lo = np.cos(row * np.pi / h), np.cos((row + 1) * np.pi / h)
    cos_t = cos_lo + (cos_hi - cos_lo) * rng.random(samples)
    u = (col + rng.random(samples)) / w
    phi = (0.5 - u) * 2.0 * np.pi
    sin_t = np.sqrt(1.0 - cos_t**2)
    omega = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    radiance_over_pdf = env.radiance[row, col] * (solid_angle[row, col] / p[idx])[:, None]
    return (np.maximum(normals @ omega.T, 0.0) @ radiance_over_pdf) / samples / np.pi


def _assert_within_2_percent(got: np.ndarray, reference: np.ndarray) -> None:
    """2% of each normal's irradiance, measured against at least a quarter of the sphere's mean:
    normals that face a dark floor while a bright light grazes their horizon receive ~5% of the mean,
    and there both the 64^2 cube's interpolation and the Monte-Carlo estimate itself are coarser."""
    scale = np.maximum(reference, 0.25 * reference.mean(axis=0, keepdims=True))
    error = np.abs(got - reference) / scale
    assert error.max() <= 0.02, f"irradiance off by {error.max():.3%} (median {np.median(error):.3%})"


@pytest.mark.parametrize("name", ["venice_sunset_1k.hdr", "studio_small_03_1k.hdr", "forest_slope_1k.hdr"])
def test_irradiance_matches_monte_carlo_of_real_hdr(gl_context, renderer, shared_data, name):
    env = _load_hdr(shared_data / "envmaps" / name)
    maps = renderer.baker.bake(env)
    try:
        normals = _random_directions(64, seed=2)
        got = sample_cube(gl_context, maps.irradiance_cube, normals)[:, :3]
        reference = _monte_carlo_irradiance(env, normals, samples=400_000, seed=3)
        _assert_within_2_percent(got, reference)
    finally:
        maps.release()


def test_specular_levels(gl_context, linear_maps):
    env, maps = linear_maps
    dirs = _random_directions(300, seed=4)
    # Roughness 0 is the environment itself.
    np.testing.assert_allclose(sample_cube(gl_context, maps.specular_cube, dirs, lod=0.0)[:, :3], 1.0 + dirs, atol=0.02)
    # Roughness 1 is a wide lobe around the direction: smoother than the source, still centred on it.
    rough = sample_cube(gl_context, maps.specular_cube, dirs, lod=float(maps.specular_levels - 1))[:, :3] - 1.0
    assert np.all(np.sum(rough * dirs, axis=1) > 0.0)
    assert np.abs(rough).max() < np.abs(dirs).max()


def test_prefiltered_constant_environment_stays_constant(gl_context, renderer):
    maps = renderer.baker.bake(Environment(np.full((64, 128, 3), 2.5, np.float32)))
    try:
        dirs = _random_directions(100, seed=5)
        for level in range(maps.specular_levels):
            got = sample_cube(gl_context, maps.specular_cube, dirs, lod=float(level))[:, :3]
            np.testing.assert_allclose(got, 2.5, rtol=0.005)
        np.testing.assert_allclose(sample_cube(gl_context, maps.irradiance_cube, dirs)[:, :3], 2.5, rtol=0.005)
    finally:
        maps.release()


def test_a_sun_keeps_its_energy_in_the_cube(gl_context, renderer):
    # A sun a few texels wide must not alias away when the panorama is resampled to a smaller cube.
    env = Environment(np.full((512, 1024, 3), 0.1, np.float32))
    env.radiance[100:104, 300:304] = 5000.0
    _, solid_angle = env.texel_directions()
    sun_dir = np.array([[0.0, 0.0, 1.0]])
    maps = renderer.baker.bake(env)
    try:
        expected = _monte_carlo_irradiance(env, sun_dir, samples=200_000, seed=6)
        got = sample_cube(gl_context, maps.irradiance_cube, sun_dir)[:, :3]
        _assert_within_2_percent(got, expected)
    finally:
        maps.release()
