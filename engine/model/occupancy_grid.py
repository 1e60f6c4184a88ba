"""Occupancy grid: which voxels of the [-R, R]^3 cube can contribute to a rendering (paper §3.4).

Built once per decoded field: the SDF is evaluated at every voxel centre and the voxel is kept when
its opacity over one ray step could reach `alpha_threshold` (paper: resolution 250, alpha < 1e-4
culled). A voxel's opacity is bounded from its centre's SDF lowered by the half diagonal, assuming
the SDF is about 1-Lipschitz (true for the analytic fields and the trained field's s_bias prior), so
a thin surface crossing a voxel corner is never culled. Pure torch, any device, queries in chunks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from .field import device_of, volsdf_density


@dataclass(frozen=True)
class OccupancyConfig:
    resolution: int = 250  # voxels per side (paper)
    alpha_threshold: float = 1e-4  # voxels whose best-case alpha is below this are culled (paper)
    chunk: int = 262144  # SDF queries per batch


class OccupancyGrid:
    def __init__(self, occupied: torch.Tensor, radius: float, opened: torch.Tensor | None = None):
        self.occupied = occupied  # (G, G, G) bool, indexed [ix, iy, iz]
        self.radius = radius
        # (G, G, G) bool or None: empty voxels that a refinement's evidence or prior opened inside the
        # object's hull (a carved opening, the hollow under it), where a stray surface is likeliest
        self.opened = opened

    @property
    def resolution(self) -> int:
        return self.occupied.shape[0]

    @property
    def occupied_fraction(self) -> float:
        return float(self.occupied.float().mean())

    @classmethod
    @torch.no_grad()
    def build(cls, field, radius: float, beta: float, step: float, config: OccupancyConfig = OccupancyConfig()) -> "OccupancyGrid":
        """`step`: the renderer's distance between samples, over which a sample's alpha is taken."""
        g = config.resolution
        voxel = 2.0 * radius / g
        centres_1d = (torch.arange(g, dtype=torch.float32) + 0.5) * voxel - radius
        half_diagonal = 0.5 * math.sqrt(3.0) * voxel
        occupied = torch.empty(g * g * g, dtype=torch.bool)
        device = device_of(field)
        for start in range(0, g * g * g, config.chunk):
            # Voxel centres of this chunk from their flat [ix, iy, iz] indices (the whole 250^3 grid
            # of coordinates would be 190 MB).
            flat = torch.arange(start, min(start + config.chunk, g * g * g))
            p = centres_1d[torch.stack([flat // (g * g), flat // g % g, flat % g], dim=-1)].to(device)
            s = field.sdf(p[None])[0]
            # The closest the surface can be to any point of the voxel, signed toward "inside".
            s_best = torch.where(s > 0, (s - half_diagonal).clamp(min=0.0), s)
            alpha = 1.0 - torch.exp(-volsdf_density(s_best, beta) / beta * step)
            occupied[start:start + config.chunk] = (alpha >= config.alpha_threshold).cpu()
        return cls(occupied.view(g, g, g).to(device), radius)

    def points_in_voxels(self, voxels: torch.Tensor, count: int, generator: torch.Generator) -> torch.Tensor:
        """`count` points spread uniformly over `voxels` ([ix, iy, iz] rows, e.g. occupied.nonzero()),
        on the grid's device; the draws come from the CPU `generator`, so they are the same on any device."""
        chosen = voxels[torch.randint(0, voxels.shape[0], (count,), generator=generator).to(voxels.device)].to(torch.float32)
        voxel = 2.0 * self.radius / self.resolution
        return -self.radius + (chosen + torch.rand(count, 3, generator=generator).to(chosen.device)) * voxel

    def lookup(self, points: torch.Tensor) -> torch.Tensor:
        """(..., 3) -> (...) bool: the point lies in an occupied voxel (points outside the cube: False)."""
        g = self.resolution
        idx = torch.floor((points + self.radius) / (2.0 * self.radius) * g).long()
        inside = ((idx >= 0) & (idx < g)).all(dim=-1)
        idx = idx.clamp(0, g - 1)
        return inside & self.occupied[idx[..., 0], idx[..., 1], idx[..., 2]]

