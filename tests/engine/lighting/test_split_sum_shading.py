"""The torch split-sum shading against the OpenGL renderer on the same G-buffer and environment."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.cameras import Camera, look_at
from lirm.engine.lighting.lighting_tables import tables_from_lighting
from lirm.engine.lighting.split_sum_shading import equirect_lookup, shade
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.primitives import uv_sphere
from lirm.renderer.procedural_environments import make_procedural_environment


def _gl_and_torch(renderer, environment, material, rotation_deg=0.0):
    lighting = renderer.prepare_lighting(environment, rotation_deg=rotation_deg)
    camera = Camera.from_fov(96, 96, 35.0, look_at((2.2, -3.0, 1.4), (0, 0, 0)))
    scene = renderer.upload([uv_sphere(0.8, segments=128, material=material)])
    try:
        out = renderer.render_view(scene, camera, lighting, RenderSettings(show_environment=False))
        tables = tables_from_lighting(renderer, lighting)
    finally:
        scene.release()
        lighting.maps.release()
    inside = out.mask > 0.99
    origins, directions = camera.pixel_rays()
    points = origins + directions * (out.depth / (directions @ camera.forward))[..., None]
    view = torch.from_numpy((origins - points)[inside]).float()
    t = lambda a: torch.from_numpy(np.ascontiguousarray(a[inside])).float()  # noqa: E731
    shaded = shade(tables, t(out.albedo), t(out.roughness), t(out.metallic), t(out.normal), view)
    return out.radiance[inside], shaded.radiance.numpy()


@pytest.mark.parametrize("environment_name,rotation", [("studio", 0.0), ("sky", 75.0)])
@pytest.mark.parametrize("roughness,metallic", [(0.25, 0.0), (0.6, 1.0), (0.45, 0.5)])
def test_torch_shading_matches_the_opengl_renderer_on_a_sphere(renderer, environment_name, rotation, roughness, metallic):
    environment = make_procedural_environment(environment_name, width=256)
    material = PBRMaterial(base_color_factor=(0.8, 0.55, 0.3, 1.0), roughness_factor=roughness, metallic_factor=metallic)
    gl, torch_radiance = _gl_and_torch(renderer, environment, material, rotation)
    assert gl.shape[0] > 2500
    # Within 1%: the sphere's total, the mean pixel error (against the mean radiance), and the typical
    # pixel against its own value. A sun's highlight at low roughness differs by a few per cent in a
    # handful of pixels (its peak is resampled from cube to equirectangular texels), so no max.
    scale = gl.mean()
    assert abs(torch_radiance.mean() - scale) / scale < 0.01
    assert np.mean(np.abs(torch_radiance - gl)) / scale < 0.01
    own = (np.abs(torch_radiance - gl) / np.maximum(gl, 1e-6)).max(axis=1)
    assert np.median(own) < 0.01 and np.quantile(own, 0.9) < 0.02


def test_the_shading_differentiates_with_respect_to_the_materials_and_the_lighting(renderer):
    lighting = renderer.prepare_lighting(make_procedural_environment("studio", width=128))
    try:
        tables = tables_from_lighting(renderer, lighting)
    finally:
        lighting.maps.release()
    tables.irradiance.requires_grad_(True)
    albedo = torch.full((8, 3), 0.5, requires_grad=True)
    roughness = torch.full((8,), 0.5, requires_grad=True)
    metallic = torch.full((8,), 0.2, requires_grad=True)
    normal = torch.nn.functional.normalize(torch.randn(8, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    view = normal + 0.3
    shade(tables, albedo, roughness, metallic, normal, view).radiance.sum().backward()
    for grad in (albedo.grad, roughness.grad, metallic.grad, tables.irradiance.grad):
        assert grad is not None and torch.isfinite(grad).all() and grad.abs().sum() > 0


def test_equirect_lookup_follows_the_environment_convention():
    environment = make_procedural_environment("sky", width=64)
    directions = np.random.default_rng(1).normal(size=(200, 3))
    expected = environment.lookup(directions)
    got = equirect_lookup(torch.from_numpy(environment.radiance), torch.from_numpy(directions).float()).numpy()
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-5)


def test_a_uniform_environment_gives_the_albedo_times_its_radiance(renderer):
    lighting = renderer.prepare_lighting(Environment(np.full((32, 64, 3), 0.7, np.float32), name="uniform"))
    try:
        tables = tables_from_lighting(renderer, lighting)
    finally:
        lighting.maps.release()
    normal = torch.tensor([[0.0, 0.0, 1.0]])
    out = shade(tables, torch.tensor([[1.0, 1.0, 1.0]]), torch.tensor([1.0]), torch.tensor([0.0]), normal, normal)
    np.testing.assert_allclose(out.radiance.numpy(), 0.7, rtol=0.01)
