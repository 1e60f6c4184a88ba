"""The lighting tabulated at fixed pixels: the same split-sum terms as the lighting it was built from."""

from __future__ import annotations

import pytest
import torch

from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.lighting.tabulated_lighting import TabulatedLighting
from lirm.renderer.procedural_environments import make_procedural_environment


def _pixels(count: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    normals = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1)
    views = torch.nn.functional.normalize(normals + 0.6 * torch.randn(count, 3, generator=g), dim=-1)
    return normals, views


def test_it_shades_as_the_lighting_it_tabulates():
    panorama = PanoramaLighting.from_environment(make_procedural_environment("studio", width=128), height=16)
    normals, views = _pixels(400)
    table = TabulatedLighting(panorama, normals, views, levels=12, chunk=128)  # several chunks
    g = torch.Generator().manual_seed(1)
    albedo, metallic = torch.rand(400, 3, generator=g), torch.rand(400, generator=g)
    with torch.no_grad():
        for roughness in (torch.full((400,), 4.0 / 11.0), 0.3 + 0.6 * torch.rand(400, generator=g)):
            exact = shade(panorama, albedo, roughness, metallic, normals, views).radiance
            tabulated = shade(table, albedo, roughness, metallic, normals, views).radiance
            # On a tabulated level it is the lighting's own value, up to the bilinear read of the fine
            # direction grid; between levels within a few per cent.
            tolerance = 1e-3 if roughness.unique().numel() == 1 else 0.03
            relative = (tabulated - exact).abs() / exact.clamp(min=1e-3)
            assert relative.median() < tolerance
            assert ((tabulated - exact).abs().mean() / exact.mean()) < max(tolerance, 0.01)
            if roughness.unique().numel() == 1:
                assert relative.quantile(0.99) < 0.01


def test_the_sharpest_lobes_read_from_the_direction_grid_as_computed_directly():
    # Roughness 0: the panorama's lobes are one texel wide, the hardest case for the grid's bilinear read.
    panorama = PanoramaLighting.from_environment(make_procedural_environment("sky", width=256), height=16)
    normals, views = _pixels(4000, seed=4)
    table = TabulatedLighting(panorama, normals, views)
    reflected = 2.0 * (normals * views).sum(-1, keepdim=True) * normals - views
    with torch.no_grad():
        exact = panorama.prefiltered(reflected, torch.zeros(4000))
        relative = (table.specular[:, 0] - exact).abs() / exact.clamp(min=1e-3)
        direct = panorama.irradiance_over_pi(normals)
        irradiance = (table.irradiance - direct).abs() / direct.mean(0)  # smooth: within a small share of its mean
    assert relative.quantile(0.99) < 0.015 and relative.max() < 0.06
    assert irradiance.quantile(0.99) < 0.002 and irradiance.max() < 0.02


def test_gradients_reach_the_roughness_and_other_pixels_are_refused():
    panorama = PanoramaLighting.from_environment(make_procedural_environment("sky", width=128), height=16)
    normals, views = _pixels(50, seed=2)
    table = TabulatedLighting(panorama, normals, views)
    roughness = torch.full((50,), 0.35, requires_grad=True)
    shade(table, torch.full((50, 3), 0.5), roughness, torch.zeros(50), normals, views).radiance.sum().backward()
    assert roughness.grad is not None and roughness.grad.abs().sum() > 0
    with pytest.raises(ValueError, match="tabulated for 50 pixels"):
        table.irradiance_over_pi(normals[:10])


def test_a_subset_of_its_rows_is_the_tabulation_of_those_pixels():
    panorama = PanoramaLighting.from_environment(make_procedural_environment("studio", width=128), height=16)
    normals, views = _pixels(60, seed=3)
    table = TabulatedLighting(panorama, normals, views)
    every_third = table.rows(slice(None, None, 3))
    direct = TabulatedLighting(panorama, normals[::3], views[::3])
    assert every_third.count == 20
    torch.testing.assert_close(every_third.irradiance, direct.irradiance)
    torch.testing.assert_close(every_third.specular, direct.specular)
    with pytest.raises(ValueError, match="tabulated for 20 pixels"):
        every_third.irradiance_over_pi(normals)


def test_its_own_shading_is_shade_and_its_brdf_the_lighting_table_read_exactly():
    """`TabulatedLighting.shade` computes only what the materials change: the same radiance and gradients
    as split_sum_shading.shade on the same table; its per-pixel BRDF rows are the panorama's table read
    at the pixel's N.V, so between rows it is the bilinear lookup itself."""
    panorama = PanoramaLighting.from_environment(make_procedural_environment("studio", width=128), height=16)
    normals, views = _pixels(300, seed=5)
    table = TabulatedLighting(panorama, normals, views)
    g = torch.Generator().manual_seed(6)
    albedo, metallic = torch.rand(300, 3, generator=g), torch.rand(300, generator=g)
    roughness = torch.cat([torch.rand(298, generator=g), torch.tensor([0.0, 1.0])])
    n_dot_v = (normals * views).sum(-1).clamp(1e-4, 1.0)
    torch.testing.assert_close(table.brdf(n_dot_v, roughness), panorama.brdf(n_dot_v, roughness), atol=1e-6, rtol=1e-5)
    inputs = [t.clone().requires_grad_(True) for t in (albedo, roughness, metallic)]
    again = [t.clone().requires_grad_(True) for t in (albedo, roughness, metallic)]
    fast = table.shade(*inputs).radiance
    general = shade(table, *again, normals, views).radiance
    torch.testing.assert_close(fast, general, atol=1e-6, rtol=1e-5)
    fast.sum().backward()
    general.sum().backward()
    for ours, theirs in zip(inputs, again):
        torch.testing.assert_close(ours.grad, theirs.grad, atol=1e-5, rtol=1e-4)
    part = table.rows(slice(None, None, 3))
    torch.testing.assert_close(part.shade(albedo[::3], roughness[::3], metallic[::3]).radiance, fast[::3].detach())


def test_pooled_terms_are_the_means_of_each_run_and_shade_a_uniform_run_as_its_members():
    panorama = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
    normals, views = _pixels(12, seed=5)
    table = TabulatedLighting(panorama, normals, views)
    pooled = table.pooled(4)
    assert pooled.count == 3
    torch.testing.assert_close(pooled.specular[1], table.specular[4:8].mean(0))
    torch.testing.assert_close(pooled.brdf_rows[2], table.brdf_rows[8:12].mean(0))
    # four copies of one pixel pool to that pixel
    same = TabulatedLighting(panorama, normals[:1].repeat(4, 1), views[:1].repeat(4, 1)).pooled(4)
    materials = (torch.tensor([[0.6, 0.3, 0.2]]), torch.tensor([0.4]), torch.tensor([0.3]))
    with torch.no_grad():
        torch.testing.assert_close(same.shade(*materials).radiance, table.rows(slice(0, 1)).shade(*materials).radiance)
    with pytest.raises(ValueError, match="whole runs of 5"):
        table.pooled(5)
