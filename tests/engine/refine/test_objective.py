"""The refinement's inverse-rendering pieces: the closed-form de-lit albedo target."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.lighting.camera_response import RESPONSES, display_to_radiance_torch, radiance_to_display_torch
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.refine.objective import delit_albedo
from lirm.renderer.procedural_environments import make_procedural_environment


def _surface(n: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    normal = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    view = torch.nn.functional.normalize(normal + 0.5 * torch.randn(n, 3, generator=g), dim=-1)
    albedo = 0.05 + 0.85 * torch.rand(n, 3, generator=g)
    roughness = 0.2 + 0.7 * torch.rand(n, generator=g)
    return normal, view, albedo, roughness


def test_the_camera_curve_inverts_in_torch():
    display = torch.linspace(0.02, 0.95, 40)[:, None] * torch.tensor([[1.0, 0.8, 0.6]])
    torch.testing.assert_close(radiance_to_display_torch(display_to_radiance_torch(display)), display, atol=1e-5, rtol=0)


@pytest.mark.parametrize("response", RESPONSES)
def test_a_shaded_photo_de_lights_to_its_albedo_even_with_metal(response):
    """Through the tone curve the capture was read with (the lighting carries it): a photo made
    through plain sRGB and read through ACES would come back far from its albedo."""
    lighting = PanoramaLighting.from_environment(make_procedural_environment("sky", width=128), height=16,
                                                 camera_response=response)
    normal, view, albedo, roughness = _surface(400)
    for metallic in (torch.zeros(400), torch.full((400,), 0.7)):
        with torch.no_grad():
            photo = radiance_to_display_torch(shade(lighting, albedo, roughness, metallic, normal, view).radiance, response)
        target, usable = delit_albedo(lighting, photo, roughness, metallic, normal, view)
        assert usable.float().mean() > 0.8  # all but clipped or unlit pixels
        error = (target[usable] - albedo[usable]).abs()
        assert error.median() < 0.01 and error.quantile(0.9) < 0.05, (metallic[0], error.quantile(0.9))


def test_baked_shading_is_removed_and_clipped_pixels_left_out():
    """The same albedo seen on a lit and a shadowed side gives the same target; a clipped pixel is no target."""
    lighting = PanoramaLighting.from_environment(make_procedural_environment("sky", width=128), height=16)
    normal = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    view = torch.nn.functional.normalize(torch.tensor([[1.0, 0.0, 1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0]]), dim=-1)
    albedo = torch.tensor([[0.6, 0.5, 0.4]] * 3)
    roughness, metallic = torch.full((3,), 0.6), torch.zeros(3)
    with torch.no_grad():
        photo = radiance_to_display_torch(shade(lighting, albedo, roughness, metallic, normal, view).radiance)
    photo[2] = 1.0  # blown out
    assert (photo[0] - photo[1]).abs().max() > 0.1  # the photo has the shading baked in
    target, usable = delit_albedo(lighting, photo, roughness, metallic, normal, view)
    assert usable.tolist() == [True, True, False]
    torch.testing.assert_close(target[0], target[1], atol=0.01, rtol=0)


def _curvature_term(field, points: int, step: float = 0.01) -> float:
    """The refinement's curvature term alone, at `points` surface points of a sphere of radius 0.5."""
    from lirm.engine.refine.config import LossWeights
    from lirm.engine.refine.objective import batch_loss
    from lirm.engine.refine.ray_rendering import RayBatchRender

    g = torch.Generator().manual_seed(0)
    on_sphere = 0.5 * torch.nn.functional.normalize(torch.randn(points, 3, generator=g), dim=-1)
    n = 8
    render = RayBatchRender(torch.ones(n, 3), torch.ones(n), torch.zeros(n, 3), torch.zeros(n), torch.zeros(n),
                            torch.zeros(n, 3), torch.zeros(n), on_sphere, 0)
    weights = LossWeights(colour=0.0, mask=0.0, eikonal=0.0, normal=0.0, albedo=0.0, material_prior=0.0,
                          curvature=1.0, curvature_step=step)
    _, terms = batch_loss(field, render, torch.ones(n, 3), torch.ones(n), weights, points, torch.Generator().manual_seed(1))
    return terms["curvature"]


def test_the_curvature_term_sees_bumps_and_not_a_smooth_sphere():
    from lirm.engine.model.analytic_fields import SphereField

    class Bumpy(SphereField):
        def sdf(self, points):
            return super().sdf(points) + 0.01 * torch.sin(60.0 * points).prod(-1)

    curvature = {name: _curvature_term(field, 256) for name, field in (("smooth", SphereField(0.5)), ("bumpy", Bumpy(0.5)))}
    assert curvature["smooth"] < 1e-3 and curvature["bumpy"] > 10 * max(curvature["smooth"], 1e-4), curvature


def test_the_curvature_step_sets_the_scale_of_the_bends_it_sees():
    # On a sphere the normals a step d apart differ by about d / r, and 1 - cos by (d / r)^2 / 2: a
    # three times longer step sees a bend nine times as large (lumps wider than a pixel are priced).
    from lirm.engine.model.analytic_fields import SphereField

    curvature = {step: _curvature_term(SphereField(0.5), 2048, step) for step in (0.01, 0.03)}
    assert 6.0 < curvature[0.03] / curvature[0.01] < 12.0, curvature


def _pair_render(albedo: torch.Tensor):
    from lirm.engine.refine.ray_rendering import RayBatchRender

    n = albedo.shape[0]
    return RayBatchRender(torch.ones(n, 3), torch.ones(n), albedo, torch.zeros(n), torch.zeros(n), torch.zeros(n, 3),
                          torch.zeros(n), torch.zeros(0, 3), 0)


def test_the_pair_term_evens_out_shading_but_not_a_change_of_paint():
    """Two pixels of one paint, one in shade, pull their albedos together; a pixel of another colour beside
    them does not; clipped and dark pixels take no part."""
    from lirm.engine.refine.objective import paired_albedo_smoothness

    paint, other = torch.tensor([0.6, 0.3, 0.2]), torch.tensor([0.2, 0.3, 0.6])
    lit, shaded = paint, 0.4 * paint  # the same chromaticity in linear light
    colours = radiance_to_display_torch(torch.stack([lit, shaded, other, 0.001 * paint]))
    alphas = torch.ones(4)
    pairs = torch.tensor([[0, 1]])
    albedo = torch.stack([lit, shaded, other, paint]).clone().requires_grad_(True)
    term = paired_albedo_smoothness(_pair_render(albedo), colours, alphas, pairs)
    assert term > 0.2  # the fit's albedo still carries the shading: penalised
    term.backward()
    assert (albedo.grad[0] * (albedo[0] - albedo[1]).detach()).sum() > 0  # descent brings them together
    for unlike in ([[0, 2]], [[0, 3]]):  # another paint; a pixel too dark to tell its colour
        assert paired_albedo_smoothness(_pair_render(albedo.detach()), colours, alphas, torch.tensor(unlike)) < 1e-3
    outside = torch.tensor([1.0, 0.0, 1.0, 1.0])  # one of the pair off the object's mask
    assert paired_albedo_smoothness(_pair_render(albedo.detach()), colours, outside, pairs) == 0


def test_neighbours_stay_in_their_view_and_within_the_radius():
    from lirm.engine.cameras import Camera
    from lirm.engine.refine.refine_views import RefineViews

    size, count = 16, 3
    cameras = [Camera.from_fov(size, size, 40.0, np.eye(4)) for _ in range(count)]
    views = RefineViews.build([f"v{i}" for i in range(count)], cameras, np.zeros((count, size, size, 3), np.float32),
                              np.ones((count, size, size), np.float32))
    g = torch.Generator().manual_seed(0)
    index = torch.randint(0, views.pixels, (2000,), generator=g)
    near = views.neighbours(index, 3, g)
    per_view = size * size
    assert torch.equal(index // per_view, near // per_view)
    y, x, y2, x2 = (index % per_view) // size, index % size, (near % per_view) // size, near % size
    assert int((y - y2).abs().max()) <= 3 and int((x - x2).abs().max()) <= 3
    interior = (y >= 3) & (y < size - 3) & (x >= 3) & (x < size - 3)
    assert not bool((near == index)[interior].any())  # never the pixel itself where there is room


def test_terms_on_surface_points_are_left_out_when_none_are_sampled():
    """With no surface points to sample (eikonal_points 0, as the starts' comparison asks), the loss
    is the other terms' sum, not NaN: a NaN made every comparison of starts False."""
    from lirm.engine.model.analytic_fields import SphereField
    from lirm.engine.refine.config import LossWeights
    from lirm.engine.refine.objective import batch_loss
    from lirm.engine.refine.ray_rendering import RayBatchRender

    n = 8
    on_sphere = 0.5 * torch.nn.functional.normalize(torch.randn(n, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    render = RayBatchRender(torch.full((n, 3), 0.5), torch.ones(n), torch.zeros(n, 3), torch.zeros(n), torch.zeros(n),
                            torch.zeros(n, 3), torch.zeros(n), on_sphere, 0)
    total, terms = batch_loss(SphereField(0.5), render, torch.ones(n, 3), torch.ones(n), LossWeights(), 0,
                              torch.Generator().manual_seed(1))
    assert torch.isfinite(total) and "curvature" not in terms and "eikonal" not in terms, terms
    weights = LossWeights()
    assert abs(float(total) - sum(getattr(weights, name) * value for name, value in terms.items())) < 1e-6
    assert abs(terms["colour"] - 0.5) < 1e-6
