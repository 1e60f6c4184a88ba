"""The pixel's footprint in the refinement's shading: the spread of normals a pixel sees on a curved
surface, and the roughness that spread widens the lobe to."""

from __future__ import annotations

import math

import pytest
import torch

from lirm.engine.model.analytic_fields import BoxField, SphereField
from lirm.engine.refine.footprint_roughness import footprint_normal_spread, widened_roughness


def _spread_facing(field, point, normal, distance, pixel_angle, direction=None):
    point, normal = torch.tensor([point]), torch.tensor([normal])
    direction = -normal if direction is None else torch.nn.functional.normalize(torch.tensor([direction]), dim=-1)
    return float(footprint_normal_spread(field, point, normal, direction, torch.tensor([distance]), torch.tensor([pixel_angle]))[0])


def test_a_sphere_seen_face_on_spreads_its_normal_by_the_footprint_over_its_radius():
    for radius in (0.5, 0.05):
        sphere = SphereField(sphere_radius=radius, normal_eps=1e-4)
        width = 2.0 * 0.01  # 2 units away, 0.01 rad a pixel
        spread = _spread_facing(sphere, (0.0, 0.0, radius), (0.0, 0.0, 1.0), 2.0, 0.01)
        # Two tangent steps of `width` on a sphere turn the normal by about width / radius each.
        turn = 2.0 * math.sin(0.5 * math.atan(width / radius))
        assert spread == pytest.approx(2.0 * turn**2 / 12.0, rel=0.05)


def test_a_flat_face_spreads_nothing_and_a_slanted_view_spreads_more():
    box = BoxField(half=(0.4, 0.4, 0.4), normal_eps=1e-4)
    assert _spread_facing(box, (0.0, 0.0, 0.4), (0.0, 0.0, 1.0), 2.0, 0.01) == pytest.approx(0.0, abs=1e-10)
    sphere = SphereField(sphere_radius=0.5, normal_eps=1e-4)
    facing = _spread_facing(sphere, (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), 2.0, 0.01)
    slanted = _spread_facing(sphere, (0.0, 0.0, 0.5), (0.0, 0.0, 1.0), 2.0, 0.01, direction=(0.0, 1.0, -0.5))
    assert slanted > 2.0 * facing  # the footprint is longer along the slant


def test_the_widened_roughness_is_the_materials_without_spread_and_grows_with_it():
    roughness = torch.tensor([0.0, 0.1, 0.5, 1.0])
    assert torch.allclose(widened_roughness(roughness, torch.zeros(4)), roughness, atol=1e-2)
    assert torch.allclose(widened_roughness(roughness[1:], torch.zeros(3)), roughness[1:], rtol=1e-5)
    wide = widened_roughness(roughness, torch.full((4,), 0.01))
    assert bool((wide >= roughness - 1e-6).all()) and float(wide[0]) == pytest.approx(0.01**0.25, rel=1e-4)
    assert float(wide[-1]) == pytest.approx(1.0)  # never beyond the roughest
    # Where the spread dominates, the material's own roughness hardly shows (the photos cannot tell).
    smooth = torch.tensor([0.05, 0.1], requires_grad=True)
    widened_roughness(smooth, torch.full((2,), 0.1)).sum().backward()
    assert float(smooth.grad.abs().max()) < 0.01
