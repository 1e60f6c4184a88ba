"""The SDF held positive outside the sampling grid (outside_bounds.py): its points lie outside the
grid with bounds no larger than their true distance from it, a surface inside the grid costs
nothing, and one grown outside it costs and is pushed back out by the term's gradient."""

from __future__ import annotations

import torch

from lirm.engine.model.occupancy_grid import OccupancyGrid
from lirm.engine.refine.outside_bounds import OutsideBounds

RESOLUTION = 32


class Ball:
    """A ball's exact SDF with a learnable radius: the least a field needs for the term."""

    def __init__(self, radius: float):
        self.radius = torch.tensor(radius, requires_grad=True)

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return points.norm(dim=-1) - self.radius


def ball_grid(radius: float) -> OccupancyGrid:
    centres = -1.0 + (torch.arange(RESOLUTION) + 0.5) * (2.0 / RESOLUTION)
    x, y, z = torch.meshgrid(centres, centres, centres, indexing="ij")
    return OccupancyGrid((x**2 + y**2 + z**2).sqrt() <= radius, 1.0)


def test_points_lie_outside_the_grid_with_bounds_below_their_distance_from_it():
    grid = ball_grid(0.5)
    outside = OutsideBounds(grid)
    points = outside.points(4000, torch.Generator().manual_seed(0), torch.device("cpu"))
    assert points.shape == (4000, 4)
    assert not grid.lookup(points[:, :3]).any()
    occupied = -1.0 + (grid.occupied.nonzero().float() + 0.5) * (2.0 / RESOLUTION)
    distance = torch.cdist(points[:, :3], occupied).min(dim=1).values
    assert (points[:, 3] >= 0).all() and (points[:, 3] <= distance + 1e-6).all()
    assert (points[:, 3] > 0).float().mean() > 0.5  # most points sit more than a voxel out


def test_a_surface_inside_the_grid_costs_nothing_and_one_outside_is_pushed_back():
    grid = ball_grid(0.5)
    outside = OutsideBounds(grid)
    points = outside.points(4000, torch.Generator().manual_seed(1), torch.device("cpu"))
    assert float(OutsideBounds.loss(Ball(0.45), points).detach()) == 0.0
    grown = Ball(0.8)  # a surface grown well past the grid, where no render looked
    optimiser = torch.optim.SGD([grown.radius], lr=0.5)
    first = float(OutsideBounds.loss(grown, points).detach())
    assert first > 0.0
    for _ in range(200):
        optimiser.zero_grad()
        OutsideBounds.loss(grown, points).backward()
        optimiser.step()
    assert float(grown.radius.detach()) < 0.58  # within a voxel or two of the grid's edge


def test_a_grid_filling_the_cube_leaves_no_points():
    grid = OccupancyGrid(torch.ones(RESOLUTION, RESOLUTION, RESOLUTION, dtype=torch.bool), 1.0)
    outside = OutsideBounds(grid)
    assert outside.empty and outside.points(10, torch.Generator(), torch.device("cpu")) is None


def test_half_the_points_fall_in_what_was_opened_inside_the_hull():
    """A shell (a ball with a hollow the carving opened): its opened inside is a few per cent of the
    empty voxels round the grid, yet it gets half the points, each bounded by its distance to the shell."""
    grid = ball_grid(0.8)
    centres = -1.0 + (torch.arange(RESOLUTION) + 0.5) * (2.0 / RESOLUTION)
    x, y, z = torch.meshgrid(centres, centres, centres, indexing="ij")
    hollow = (x**2 + y**2 + z**2).sqrt() <= 0.5
    shell = OccupancyGrid(grid.occupied & ~hollow, 1.0, opened=hollow)
    points = OutsideBounds(shell).points(4000, torch.Generator().manual_seed(0), torch.device("cpu"))
    inside = points[:, :3].norm(dim=-1) <= 0.5 + 2.0 / RESOLUTION
    assert 0.45 < inside.float().mean() < 0.55
    assert not shell.lookup(points[:, :3]).any()
    assert points[inside, 3].max() > 0.2  # the hollow's middle lies 0.5 from the shell: its points say so
    occupied = -1.0 + (shell.occupied.nonzero().float() + 0.5) * (2.0 / RESOLUTION)
    assert (points[:, 3] <= torch.cdist(points[:, :3], occupied).min(dim=1).values + 1e-6).all()
    # Without the opened voxels marked, the same shell's points fall in its hollow a few per cent of the time.
    plain = OutsideBounds(OccupancyGrid(shell.occupied, 1.0)).points(4000, torch.Generator().manual_seed(0), torch.device("cpu"))
    assert (plain[:, :3].norm(dim=-1) <= 0.5 + 2.0 / RESOLUTION).float().mean() < 0.15
