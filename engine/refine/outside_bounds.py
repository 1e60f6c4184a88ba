"""Empty where the fit never looks: the SDF held positive outside the sampling bounds.

The fit renders samples only inside its occupancy grid (the masks' hull, carved where the photos
see through it, then dilated); outside, every render is empty whatever the field holds there. But
the field's planes are shared by every point, so the steps that shape the surface inside the grid
also move the SDF outside it, unwatched: a mug's opening, carved from the grid because the photos
see into it, filled again with a lid that no render ever showed, and the export (marching cubes over
the whole cube) kept it (README, "What the photos see through the hull"). The prior: a point
outside the grid is at least its distance to the grid's nearest occupied voxel from the surface
(the surface lies inside the grid), a hinge on points spread over the empty voxels near the grid,
where a stray surface would join the object.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy import ndimage

from lirm.engine.model.occupancy_grid import OccupancyGrid

REACH_VOXELS = 16  # how far from the grid's occupied voxels the points are spread


class OutsideBounds:
    def __init__(self, grid: OccupancyGrid, reach_voxels: int = REACH_VOXELS):
        occupied = grid.occupied.cpu().numpy().astype(bool)
        distance = ndimage.distance_transform_edt(~occupied)  # voxels, centre to nearest occupied centre
        near = ~occupied & (distance <= reach_voxels)
        self._radius = grid.radius
        self._voxel = 2.0 * grid.radius / grid.resolution
        self._voxels = torch.from_numpy(np.argwhere(near)).long()
        # A point anywhere in its voxel is at least a voxel less than the centres' distance from the grid.
        self._bounds = torch.from_numpy(np.maximum(distance[near] - 1.0, 0.0).astype(np.float32)) * self._voxel

    @property
    def empty(self) -> bool:
        return self._voxels.shape[0] == 0

    def points(self, count: int, generator: torch.Generator, device: torch.device) -> torch.Tensor | None:
        """(count, 4): points spread over the empty voxels near the grid, with the SDF's lower bound at each
        (None when the grid leaves none)."""
        if self.empty:
            return None
        pick = torch.randint(0, self._voxels.shape[0], (count,), generator=generator)
        corner = self._voxels[pick].to(torch.float32)
        points = -self._radius + (corner + torch.rand(count, 3, generator=generator)) * self._voxel
        return torch.cat([points, self._bounds[pick, None]], dim=1).to(device)

    @staticmethod
    def loss(field, points: torch.Tensor) -> torch.Tensor:
        """Mean shortfall of the SDF below its lower bound at `points` (from `points`)."""
        return OutsideBounds.shortfall(points[:, 3], field.sdf(points[None, :, :3])[0])

    @staticmethod
    def shortfall(bounds: torch.Tensor, sdf: torch.Tensor) -> torch.Tensor:
        """Mean of how far each SDF value falls below its bound."""
        return torch.relu(bounds - sdf).mean()
