"""The search over material hypotheses: on pixels shaded from known materials, it finds the metal
and the roughness the gradient does not reach, and leaves paint as paint."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.refine.config import MaterialSearchSettings
from lirm.engine.refine.material_search import SurfacePixels, choose_materials
from lirm.renderer.procedural_environments import make_procedural_environment

GOLD, PAINT = torch.tensor([0.95, 0.7, 0.3]), torch.tensor([0.6, 0.3, 0.2])


def _sphere_pixels(lighting, views: int = 16, per_view: int = 3000) -> tuple[SurfacePixels, torch.Tensor]:
    """A sphere of radius 0.6 seen from `views` directions round it: its x < 0 half gold metal of
    roughness 0.15, the other half a rough red paint; the field's own pair everywhere (0.5, 0), where
    a refinement starts. Returns the pixels and which of them are metal."""
    generator = torch.Generator().manual_seed(0)
    points, normals, eyes = [], [], []
    for k in range(views):
        angle = 2.0 * torch.pi * k / views
        eye = torch.tensor([torch.cos(torch.tensor(angle)), torch.sin(torch.tensor(angle)), 0.3 * (-1) ** k])
        eye = F.normalize(eye, dim=0)
        n = F.normalize(torch.randn(per_view * 3, 3, generator=generator), dim=-1)
        n = n[(n @ eye) > 0.2][:per_view]  # the part of the sphere this view sees
        points.append(0.6 * n)
        normals.append(n)
        eyes.append(F.normalize(3.0 * eye - 0.6 * n, dim=-1))
    points, normals, views_ = torch.cat(points), torch.cat(normals), torch.cat(eyes)
    metal = points[:, 0] < 0.0
    albedo = torch.where(metal[:, None], GOLD, PAINT)
    roughness = torch.where(metal, 0.15, 0.7)
    shaded = shade(lighting, albedo, roughness, metal.float(), normals, views_).radiance
    colour = radiance_to_display_torch(shaded).clamp(0.0, 1.0)
    own = torch.full((points.shape[0],), 0.5), torch.zeros(points.shape[0])
    return SurfacePixels(points, normals, views_, colour, *own), metal


def test_the_search_finds_the_metal_and_its_roughness_and_keeps_paint_paint():
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=128), height=16)
    pixels, metal = _sphere_pixels(lighting)
    with torch.no_grad():
        choice = choose_materials(lighting, pixels, 1.0, MaterialSearchSettings())
    roughness, metallic, chosen = choice.lookup(pixels.points)
    assert metallic[metal].mean() > 0.9, f"metal found at {float(metallic[metal].mean()):.2f} of the gold half"
    assert metallic[~metal].mean() < 0.1, "the paint was made metal"
    # The gold half's roughness comes down from the field's 0.5 to the grid's levels at most one from 0.15.
    assert roughness[metal].median() <= 0.25
    assert 0.4 <= roughness[~metal].median() <= 0.85
    assert choice.shares["metal"] > 0.3 and abs(sum(choice.shares.values()) - 1.0) < 1e-6


def test_the_field_own_pair_is_kept_where_it_explains_the_pixels_and_the_anchor_falls_back_elsewhere():
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=128), height=16)
    pixels, metal = _sphere_pixels(lighting)
    # The field already has the truth: nothing beats it by the margin, so nothing is chosen.
    truth = SurfacePixels(pixels.points, pixels.normal, pixels.view, pixels.colour,
                          torch.where(metal, 0.15, 0.7), metal.float())
    with torch.no_grad():
        choice = choose_materials(lighting, truth, 1.0, MaterialSearchSettings())
    assert choice.shares["kept"] > 0.9
    fallback = lambda p: (torch.full((p.shape[0],), 0.375), torch.full((p.shape[0],), 0.25))  # noqa: E731
    far_away = torch.tensor([[0.95, 0.95, 0.95]])  # a cell no pixel fell in
    r, m = choice.anchor(fallback)(far_away)
    assert float(r) == 0.375 and float(m) == 0.25
    r, m = choice.anchor(None)(far_away)
    assert float(r) == 0.5 and float(m) == 0.0
