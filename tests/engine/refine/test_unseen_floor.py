"""The floor prior (refine/unseen_floor.py): the floor follows the lowest surface the views see, its
term removes the wedge the masks' hull leaves under an object seen from above, and nothing the views
see is cut."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from lirm.engine.cameras import orbit_cameras
from lirm.engine.model.analytic_fields import BoxField
from lirm.engine.model.config import preset
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import LossWeights, RefineConfig
from lirm.engine.refine.ray_rendering import render_ray_batch
from lirm.engine.refine.refine_views import RefineViews
from lirm.engine.refine.refiner import refine_field
from lirm.engine.refine.unseen_floor import UnseenFloor

BOTTOM = -0.2  # the box's underside


class Box(BoxField):
    def sample(self, points, directions=None, materials=True):
        return super().sample(points, directions)


@pytest.fixture(scope="module")
def box_views(analytic_views) -> RefineViews:
    """8 views of a box from 30 degrees above the horizon, 64 px: its underside is never seen."""
    return analytic_views(Box(half=(0.4, 0.3, -BOTTOM)), orbit_cameras(8, 30.0, 2.6, 64, 64, 50.0))


def _grid(views):
    return initial_fields.sampling_grid(initial_fields.masks_hull(views, 48, 1.0), 1.0, 2)


def test_the_floor_settles_just_under_the_lowest_seen_surface(box_views):
    truth, grid = Box(half=(0.4, 0.3, -BOTTOM)), _grid(box_views)
    floor = UnseenFloor(grid, 1.0)
    generator = torch.Generator().manual_seed(0)
    for _ in range(30):
        index = box_views.sample_rays(1024, 0.25, generator)
        out = render_ray_batch(truth, box_views.origins[index], box_views.directions[index], grid, 1 / 250, 48, 16, generator)
        floor.observe(box_views.origins[index], box_views.directions[index], out.depth, out.opacity,
                      box_views.alphas[index], box_views.pixel_angles[index], 1 / 250)
    # Below the underside (never above it), by no more than a pixel's footprint, the blur and the margin.
    assert BOTTOM - 0.06 < floor.height < BOTTOM, floor.height
    # The hull hangs below the box: there are points under the floor, and the box meets its bound there.
    points = floor.points_below(500, generator, torch.device("cpu"))
    assert points is not None and float(points[:, 2].max()) <= floor.height
    assert float(floor.loss(truth, points)) == 0.0
    lower = Box(half=(0.4, 0.3, 0.35))  # a box reaching below the floor breaks the bound
    assert float(floor.loss(lower, points)) > 0.0


def test_no_floor_before_anything_is_seen(box_views):
    floor = UnseenFloor(_grid(box_views), 1.0)
    n = 100
    floor.observe(torch.zeros(n, 3), torch.ones(n, 3), torch.zeros(n), torch.zeros(n), torch.ones(n), torch.ones(n), 0.01)
    assert floor.height is None and floor.points_below(10, torch.Generator(), torch.device("cpu")) is None


def _bottom_after_fit(views, floor_weight: float) -> float:
    """The SDF's zero crossing on the box's vertical axis below its centre, after a short fit from scratch."""
    config = RefineConfig(minutes=None, iterations=300, rays_per_step=512, coarse_samples=24, fine_samples=8,
                          plane_resolutions=(16, 32), eikonal_points=256, best_every=10, hull_resolution=32,
                          losses=replace(LossWeights(), floor=floor_weight))
    result = refine_field(initial_fields.scratch(preset("tiny"), 16, 0), views, config, _grid(views))
    z = torch.linspace(-0.6, 0.0, 241)
    with torch.no_grad():
        sdf = result.field.frozen_field().sdf(torch.stack([torch.zeros_like(z), torch.zeros_like(z), z], -1)[None])[0]
    inside = (sdf < 0).nonzero()
    return float(z[inside[0, 0]]) if len(inside) else 0.0


def test_the_floor_term_removes_the_wedge_under_the_box_and_keeps_the_box(box_views):
    without, with_floor = _bottom_after_fit(box_views, 0.0), _bottom_after_fit(box_views, 0.5)
    assert without < BOTTOM - 0.08  # the hull's wedge: the views cannot tell it from the box
    assert BOTTOM - 0.07 < with_floor < BOTTOM + 0.03, (without, with_floor)
