"""The floor under what the photos see: a prior for the underside that no photo shows.

Photos are taken from above an object standing on something (the capture's +Z is the cameras' mean
up), so its underside is never seen, and the masks' visual hull leaves a wedge hanging below it
(views at 20-40 degrees above the horizon leave one about a third of the object's width deep). Every
photo agrees with that wedge, so the photometric and mask terms never remove it; it was most of the
toy block's Chamfer error after a 3-minute refinement (README: "Per-scene refinement").

The prior: nothing lies below the lowest surface the photos see. Along every ray inside a mask the
expected surface point (the rendering weights' mean depth) is a seen point, known to within a pixel's
footprint and the surface's blur (a few beta); the lowest of them, lowered by those and a margin, is
this batch's floor, and the floor follows it over steps. Below it the SDF must be at least the
height below the floor (the true SDF is, when the object is above it): a hinge on points spread over
the hull's voxels below the floor.

It cannot ratchet up into the object: where it cuts, the walls are seen down to the cut, and their
lowest point less the margins lies below it, so the floor sinks back to the lowest seen surface.
When the photos do see the underside (views from below), the floor is the true bottom and the prior
removes nothing; under a round bottom seen from above it flattens the cap no photo saw.
"""

from __future__ import annotations

import torch

from lirm.engine.model.occupancy_grid import OccupancyGrid

MARGIN = 0.01  # of the bounding radius, below the lowest seen point less its footprint and blur
BLUR_BETAS = 2.0  # the expected surface point lies within about this many beta of the SDF's zero
LOWEST_QUANTILE = 0.002  # the batch's lowest seen points (a quantile, not the minimum: one stray ray)
MOMENTUM = 0.9  # of the running floor height over steps
MIN_SEEN_RAYS = 64  # fewer seen rays in a batch than this say nothing about the floor


class UnseenFloor:
    def __init__(self, grid: OccupancyGrid | None, radius: float):
        self.radius = radius
        self.height: float | None = None  # the running floor height (world z); None until rays have seen a surface
        self._grid = grid
        self._voxels = None if grid is None else grid.occupied.nonzero()

    @torch.no_grad()
    def observe(self, origins: torch.Tensor, directions: torch.Tensor, depth: torch.Tensor, opacity: torch.Tensor,
                alphas: torch.Tensor, pixel_angles: torch.Tensor, beta: float) -> None:
        """Update the floor from a batch: `depth` premultiplied by `opacity` as rendered, `alphas` the
        masks, `pixel_angles` the angle each ray's pixel spans, `beta` the current VolSDF beta."""
        seen = (alphas > 0.5) & (opacity > 0.5)
        if int(seen.sum()) < MIN_SEEN_RAYS:
            return
        t = depth[seen] / opacity[seen]
        z = origins[seen, 2] + t * directions[seen, 2]
        low = z - t * pixel_angles[seen] - BLUR_BETAS * beta
        lowest = float(torch.quantile(low, LOWEST_QUANTILE)) - MARGIN * self.radius
        self.height = lowest if self.height is None else MOMENTUM * self.height + (1.0 - MOMENTUM) * lowest

    def points_below(self, count: int, generator: torch.Generator, device: torch.device) -> torch.Tensor | None:
        """Up to `count` points spread over the hull's voxels below the floor (None: none there, or no floor yet)."""
        if self.height is None or self._voxels is None:
            return None
        grid = self._grid
        top = (self._voxels[:, 2] + 1) * (2.0 * grid.radius / grid.resolution) - grid.radius  # each voxel's upper face
        below = self._voxels[top <= self.height]
        if below.shape[0] == 0:
            return None
        return grid.points_in_voxels(below, count, generator).to(device)

    def loss(self, field, points: torch.Tensor) -> torch.Tensor:
        """Mean shortfall of the SDF below its lower bound, the height under the floor."""
        bound = self.height - points[:, 2]
        return torch.relu(bound - field.sdf(points[None])[0]).mean()
