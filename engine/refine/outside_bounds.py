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
# The share of the points in the grid's opened voxels (OccupancyGrid.opened), when it has any. Spread
# evenly, 2-3% of them fell in the synthetic mug's opened inside (the rest in the open air round it),
# 9-14 of 512 a step, and the fit filled the hollow and closed the opening with a lid no render showed.
OPENED_SHARE = 0.5


class OutsideBounds:
    def __init__(self, grid: OccupancyGrid, reach_voxels: int = REACH_VOXELS, opened_share: float = OPENED_SHARE):
        occupied = grid.occupied.cpu().numpy().astype(bool)
        distance = ndimage.distance_transform_edt(~occupied)  # voxels, centre to nearest occupied centre
        near = ~occupied & (distance <= reach_voxels)
        self._radius = grid.radius
        self._voxel = 2.0 * grid.radius / grid.resolution
        opened = np.zeros_like(near) if grid.opened is None else grid.opened.cpu().numpy().astype(bool) & near
        # The opened voxels first, then the rest: `points` draws from each part its share.
        order = np.concatenate([np.argwhere(opened), np.argwhere(near & ~opened)])
        self._voxels = torch.from_numpy(order).long()
        self._opened = int(opened.sum())
        self._opened_share = opened_share if 0 < self._opened < len(order) else float(self._opened == len(order))
        # A point anywhere in its voxel is at least a voxel less than the centres' distance from the grid.
        bounds = np.maximum(distance[tuple(order.T)] - 1.0, 0.0) if len(order) else np.zeros(0)
        self._bounds = torch.from_numpy(bounds.astype(np.float32)) * self._voxel

    @property
    def empty(self) -> bool:
        return self._voxels.shape[0] == 0

    def points(self, count: int, generator: torch.Generator, device: torch.device) -> torch.Tensor | None:
        """(count, 4): points spread over the empty voxels near the grid, with the SDF's lower bound at each
        (None when the grid leaves none)."""
        if self.empty:
            return None
        in_opened = round(count * self._opened_share)
        pick = torch.cat([torch.randint(0, max(self._opened, 1), (in_opened,), generator=generator),
                          torch.randint(self._opened, max(self._voxels.shape[0], self._opened + 1), (count - in_opened,),
                                        generator=generator)])
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
