"""Where a refinement starts: the hull's shape with another field's materials (`--init hull-lirm`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.cameras import orbit_cameras
from lirm.engine.model.analytic_fields import SphereField
from lirm.engine.model.config import preset
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig


def test_materials_are_read_at_the_fields_own_surface_nearest_each_point():
    """A point outside a sphere reads the roughness at the sphere's surface point nearest it, not
    at itself (the roughness ramps along x, so the two differ)."""
    materials = SphereField(sphere_radius=0.5, center=(0.3, 0.0, 0.0))
    points = torch.tensor([[[-0.7, 0.0, 0.0], [0.3, 0.0, 0.75]]])
    roughness, metallic = initial_fields.materials_near(materials, points)
    surface = torch.tensor([[[-0.2, 0.0, 0.0], [0.3, 0.0, 0.5]]])
    expected = materials.sample(surface).roughness
    assert torch.allclose(roughness, expected, atol=1e-3), (roughness, expected)
    assert abs(float(roughness[0, 0]) - float(materials.sample(points).roughness[0, 0])) > 0.1


def test_the_hull_start_takes_the_other_fields_materials(analytic_views):
    """Regressed onto the hull of a sphere's masks with a glossy, metal prediction beside it, the start
    carries that prediction on its surface; without it, it knows nothing of it."""
    views = analytic_views(SphereField(sphere_radius=0.5), orbit_cameras(6, 20.0, 2.6, 32, 32, 50.0))
    hull = initial_fields.masks_hull(views, 32, 1.0)
    config = preset("tiny")
    prediction = initial_fields.scratch(config, 16, seed=3)
    with torch.no_grad():  # glossy metal everywhere
        prediction.heads.roughness[-1].bias.fill_(-2.0)
        prediction.heads.metallic[-1].bias.fill_(2.0)
    target = prediction.frozen_field().sample(torch.zeros(1, 1, 3))
    surface = 0.5 * torch.nn.functional.normalize(torch.randn(1, 256, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    found = {}
    for with_materials in (True, False):
        start = initial_fields.from_hull(hull, config, None, 16, steps=120, seed=1,
                                         materials=prediction.frozen_field() if with_materials else None)
        sample = start.frozen_field().sample(surface)
        found[with_materials] = (float(sample.roughness.mean()), float(sample.metallic.mean()))
        assert float(start.frozen_field().sdf(torch.zeros(1, 1, 3))) < 0  # the hull's inside stays inside
    assert found[True][0] == pytest.approx(float(target.roughness), abs=0.08), (found, float(target.roughness))
    assert found[True][1] == pytest.approx(float(target.metallic), abs=0.08), (found, float(target.metallic))
    assert abs(found[False][1] - float(target.metallic)) > 0.3, found


def test_the_auto_start_takes_whichever_field_agrees_better_with_the_photos(analytic_views):
    """`closer_start` (what `lirm refine` and `lirm bench refine --init auto` start a capture from):
    a field regressed onto the photos' hull wins over an untrained one whichever slot it is given in."""
    views = analytic_views(SphereField(sphere_radius=0.5), orbit_cameras(6, 20.0, 2.6, 32, 32, 50.0))
    hull = initial_fields.masks_hull(views, 32, 1.0)
    config = preset("tiny")
    near = initial_fields.from_hull(hull, config, None, 16, steps=120, seed=1)
    far = initial_fields.scratch(config, 16, seed=3)
    refine = RefineConfig(coarse_samples=24, fine_samples=8)
    start, chosen, losses = initial_fields.closer_start(far, near, views, None, refine)
    assert chosen == "hull-lirm" and start is near and losses["hull-lirm"] < losses["lirm"], losses
    start, chosen, losses = initial_fields.closer_start(near, far, views, None, refine)
    assert chosen == "lirm" and start is near and losses["lirm"] < losses["hull-lirm"], losses
    # Judged on the rays the fit draws (those that meet the hull, `rays_through_hull`): the same choice,
    # and both losses larger, since the rays every start gets right (the empty background) are left out.
    grid = initial_fields.sampling_grid(hull, 1.0, dilation_voxels=1)
    through = RefineConfig(coarse_samples=24, fine_samples=8, rays_through_hull=True)
    _, chosen_all, losses_all = initial_fields.closer_start(near, far, views, grid, refine)
    start, chosen, losses = initial_fields.closer_start(near, far, views, grid, through)
    assert chosen == chosen_all == "lirm" and start is near
    assert losses["hull-lirm"] > losses_all["hull-lirm"], (losses, losses_all)


def test_the_footprint_hull_is_a_third_candidate_and_wins_when_it_is_closest(analytic_views):
    """With `from_footprint_hull`, the closest of three starts is taken, whichever it is: the field
    regressed onto the hull beats two untrained ones from either hull slot."""
    views = analytic_views(SphereField(sphere_radius=0.5), orbit_cameras(6, 20.0, 2.6, 32, 32, 50.0))
    footprint = initial_fields.masks_hull(views, 32, 1.0, footprint=True)
    centres = initial_fields.masks_hull(views, 32, 1.0)
    # The footprint carve keeps every voxel the centre test keeps, and more.
    assert (footprint.occupancy | centres.occupancy).sum() == footprint.occupancy.sum() > centres.occupancy.sum()
    config = preset("tiny")
    near = initial_fields.from_hull(footprint, config, None, 16, steps=120, seed=1)
    far, farther = initial_fields.scratch(config, 16, seed=3), initial_fields.scratch(config, 16, seed=4)
    refine = RefineConfig(coarse_samples=24, fine_samples=8)
    start, chosen, losses = initial_fields.closer_start(far, farther, views, None, refine, near)
    assert chosen == "hull-lirm-footprint" and start is near and set(losses) == {"lirm", "hull-lirm", "hull-lirm-footprint"}
    assert losses["hull-lirm-footprint"] < min(losses["lirm"], losses["hull-lirm"]), losses
    start, chosen, _ = initial_fields.closer_start(far, near, views, None, refine, farther)
    assert chosen == "hull-lirm" and start is near


def _carved_masks(hits, resolution: int = 32, size: int = 64):
    """The centres' and the footprint hulls of 16 views' exact masks of a shape: `hits(origin, directions)`
    says which rays (N, 3) meet it."""
    from lirm.engine.cameras import orbit_camera
    from lirm.engine.evaluation.carved_hull import CarvedHull

    cameras, masks = [], []
    for elevation in (20.0, 40.0):
        for azimuth in range(10, 360, 45):
            camera = orbit_camera(azimuth, elevation, 2.6, size, size, 50.0)
            directions = camera.plucker().astype(np.float64).reshape(-1, 3 + 3)[:, :3]
            masks.append(hits(camera.center, directions).reshape(size, size))
            cameras.append(camera)
    images = [np.zeros(m.shape + (3,)) for m in masks]
    hulls = []
    for footprint in (False, True):
        hull = CarvedHull(image_size=size, resolution=resolution, footprint=footprint)
        hulls.append(hull.update_known(hull.initial_state(1), cameras, images, masks))
    return hulls


def _ball_hits(origin, directions, radius: float = 0.5):
    along = directions @ origin  # rays of unit direction: the nearest approach to the centre
    return np.dot(origin, origin) - along ** 2 < radius ** 2


def _panel_hits(origin, directions, height: float, half: float = 0.4):
    t = (height - origin[1]) / directions[:, 1]  # a square of no thickness in the plane y = height
    x, z = origin[0] + t * directions[:, 0], origin[2] + t * directions[:, 2]
    return (t > 0) & (np.abs(x) <= half) & (np.abs(z) <= half)


def test_the_footprint_hull_is_a_candidate_only_where_it_kept_lost_parts():
    """`footprint_keeps_lost_parts` decides whether the footprint hull is worth a start of its own: not
    for a ball (there it is the centres' hull a voxel fatter), yes for a panel thinner than a voxel
    (the centre test carved most of it away)."""
    voxel = 2.0 / 32
    ball = _carved_masks(_ball_hits)
    panel = _carved_masks(lambda origin, directions: _panel_hits(origin, directions, 0.02 * voxel))
    for centres, footprint in (ball, panel):
        assert footprint.occupancy.sum() > centres.occupancy.sum()
    assert not initial_fields.footprint_keeps_lost_parts(*ball)
    assert initial_fields.footprint_keeps_lost_parts(*panel)
    # A footprint hull carved away entirely has nothing to add; where the centre test kept nothing at
    # all, whatever the footprint kept was lost by it.
    centres, footprint = panel
    assert not initial_fields.footprint_keeps_lost_parts(centres, replace(footprint, occupancy=np.zeros_like(footprint.occupancy)))
    assert initial_fields.footprint_keeps_lost_parts(replace(centres, occupancy=None), footprint)


def test_the_sampling_grid_marks_what_was_opened_for_the_outside_term():
    """What the carving and the hollow opened, less what the dilation (slack for the masks' edges)
    gives back, is marked in the grid: the outside term puts half its points there."""
    from scipy import ndimage

    from lirm.engine.evaluation.carved_hull import CarvedHullState

    r = 24
    index = np.indices((r, r, r)).transpose(1, 2, 3, 0) - (r - 1) / 2.0
    ball = np.linalg.norm(index, axis=-1) <= 9.0
    opened = ball & (np.linalg.norm(index, axis=-1) <= 6.0)
    hull = CarvedHullState(ball & ~opened, np.zeros((r, r, r, 3)), np.zeros((r, r, r)))
    plain = initial_fields.sampling_grid(hull, 1.0, 2)
    grid = initial_fields.sampling_grid(hull, 1.0, 2, opened=opened)
    two = ndimage.binary_dilation(ball & ~opened, iterations=2)
    assert torch.equal(plain.occupied, torch.from_numpy(two)) and torch.equal(grid.occupied, plain.occupied)
    assert torch.equal(grid.opened, torch.from_numpy(opened & ~two)) and grid.opened.sum() > 50
    assert plain.opened is None
