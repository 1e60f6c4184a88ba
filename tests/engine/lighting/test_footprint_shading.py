"""The texture fit's shading with its hand-written backward (footprint_shading.py): the values and
gradients of TabulatedLighting.shade followed by the footprint's mean."""

from __future__ import annotations

import pytest
import torch

from lirm.engine.lighting.footprint_shading import shade_footprints
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.tabulated_lighting import TabulatedLighting
from lirm.renderer.procedural_environments import make_procedural_environment


def _tabulated(count: int, seed: int = 0) -> TabulatedLighting:
    g = torch.Generator().manual_seed(seed)
    normals = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1)
    views = torch.nn.functional.normalize(normals + 0.6 * torch.randn(count, 3, generator=g), dim=-1)
    panorama = PanoramaLighting.from_environment(make_procedural_environment("sky", width=64), height=8)
    table = TabulatedLighting(panorama, normals, views, levels=12)
    for name in ("irradiance", "specular", "brdf_rows", "n_dot_v", "fresnel"):  # in double, to compare closely
        setattr(table, name, getattr(table, name).double())
    return table


def _reference(lighting: TabulatedLighting, reads: torch.Tensor, footprint: int) -> torch.Tensor:
    return lighting.shade(reads[:, :3], reads[:, 3], reads[:, 4]).radiance.reshape(-1, footprint, 3).mean(1)


@pytest.mark.parametrize("footprint", [1, 4])
def test_values_and_gradients_are_the_split_sum_shadings_mean(footprint):
    lighting = _tabulated(240)
    g = torch.Generator().manual_seed(1)
    reads = torch.rand(240, 5, generator=g, dtype=torch.float64)
    # roughness at both ends of the tables, on a BRDF row's centre, and where 1 - r meets f0
    reads[:6, 3] = torch.tensor([0.0, 1.0, 0.5 / 32, 4.0 / 11.0, 0.999, 0.02], dtype=torch.float64)
    reads[6:9, 4] = torch.tensor([0.0, 1.0, 0.5], dtype=torch.float64)
    ours, theirs = reads.clone().requires_grad_(True), reads.clone().requires_grad_(True)
    shaded, expected = shade_footprints(lighting, ours, footprint), _reference(lighting, theirs, footprint)
    assert shaded.shape == (240 // footprint, 3)
    torch.testing.assert_close(shaded, expected, atol=1e-12, rtol=1e-12)
    weights = torch.randn(shaded.shape, generator=g, dtype=torch.float64)
    (shaded * weights).sum().backward()
    (expected * weights).sum().backward()
    torch.testing.assert_close(ours.grad, theirs.grad, atol=1e-10, rtol=1e-9)


def test_it_passes_torch_gradcheck():
    lighting = _tabulated(12, seed=3)
    g = torch.Generator().manual_seed(4)
    # away from the kinks (a table row's edge, 1 - r = f0), where a finite difference straddles them
    reads = (0.1 + 0.8 * torch.rand(12, 5, generator=g, dtype=torch.float64)).requires_grad_(True)
    assert torch.autograd.gradcheck(lambda r: shade_footprints(lighting, r, 2), (reads,), eps=1e-7, atol=1e-6)


def test_wrong_counts_are_refused():
    lighting = _tabulated(8)
    with pytest.raises(ValueError, match="tabulated for 8 pixels, not 6"):
        shade_footprints(lighting, torch.rand(6, 5, dtype=torch.float64), 2)
    with pytest.raises(ValueError, match="whole footprints of 3"):
        shade_footprints(lighting, torch.rand(8, 5, dtype=torch.float64), 3)
