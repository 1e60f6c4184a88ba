"""A lighting's split-sum terms tabulated once at fixed surface pixels, for fits where only the materials move.

When the normals and view directions are fixed (a mesh seen from known cameras) and only the albedo,
roughness and metallic are fitted, the lighting's irradiance and prefiltered specular at each pixel
depend on nothing but the roughness. They are computed once: the irradiance per pixel, and the
prefiltered specular at `levels` evenly spaced roughness values, interpolated linearly between them
(as the renderer's mip chain interpolates between its prefiltered levels). Each fitting step then
costs a gather instead of the panorama's full lobe sum over every texel.

A fittable panorama's terms are first computed on a fine equirectangular grid of directions (8 x the
panorama's resolution) and read from it per pixel: its lobes are never narrower than one of its own
texels, so the grid resolves them (within a fraction of a per cent; tested), and computing the lobe
sums for a million photo pixels directly took 85 s of the demo's 171 s texture fit.

It keeps `split_sum_shading.shade`'s lighting interface; the directions `shade` passes are ignored
(they are the tabulated ones), so it must be called on exactly the pixels it was built for.
"""

from __future__ import annotations

import numpy as np
import torch

from lirm.renderer.environment import Environment

from .panorama_lighting import PanoramaLighting
from .split_sum_shading import equirect_lookup

# Directions per panorama texel side on the grid a panorama's terms are computed on first.
PANORAMA_GRID_FACTOR = 8


class _OnDirectionGrid:
    """A panorama's irradiance and prefiltered specular computed once per roughness level on a grid of
    directions, then read bilinearly (the renderer reads its prefiltered maps the same way)."""

    def __init__(self, lighting: PanoramaLighting, roughness_levels: torch.Tensor):
        height = int(lighting.log_radiance.shape[0]) * PANORAMA_GRID_FACTOR
        directions, _ = Environment(np.zeros((height, 2 * height, 3), np.float32)).texel_directions()
        grid = torch.from_numpy(directions.reshape(-1, 3)).to(roughness_levels)
        self.irradiance = lighting.irradiance_over_pi(grid).reshape(height, 2 * height, 3)
        self.specular = [lighting.prefiltered(grid, torch.full((grid.shape[0],), float(r), dtype=grid.dtype,
                                                               device=grid.device)).reshape(height, 2 * height, 3)
                         for r in roughness_levels]

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        return equirect_lookup(self.irradiance, normals)

    def prefiltered_levels(self, reflected: torch.Tensor) -> torch.Tensor:
        return torch.stack([equirect_lookup(level, reflected) for level in self.specular], dim=1)


class TabulatedLighting:
    def __init__(self, lighting, normals: torch.Tensor, views: torch.Tensor, levels: int = 12, chunk: int = 16_384):
        """`lighting`: anything `shade` accepts (a PanoramaLighting, SplitSumTables); `normals`, `views`:
        (N, 3) unit world normals and surface-to-eye directions of the pixels."""
        if levels < 2:
            raise ValueError(f"levels must be at least 2, got {levels}")
        self.lighting = lighting
        self.levels = levels
        self.count = normals.shape[0]
        n = normals / normals.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        v = views / views.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        reflected = 2.0 * (n * v).sum(-1, keepdim=True) * n - v  # GLSL reflect(-v, n), as `shade` takes it
        roughness_levels = torch.linspace(0.0, 1.0, levels, dtype=n.dtype, device=n.device)
        irradiance, specular = [], []
        with torch.no_grad():
            grid = _OnDirectionGrid(lighting, roughness_levels) if isinstance(lighting, PanoramaLighting) else None
            for start in range(0, self.count, chunk):
                part_n, part_r = n[start:start + chunk], reflected[start:start + chunk]
                if grid is not None:
                    irradiance.append(grid.irradiance_over_pi(part_n))
                    specular.append(grid.prefiltered_levels(part_r))
                    continue
                irradiance.append(lighting.irradiance_over_pi(part_n))
                specular.append(torch.stack([lighting.prefiltered(part_r, torch.full((part_r.shape[0],), float(r), dtype=n.dtype,
                                                                                     device=n.device))
                                             for r in roughness_levels], dim=1))
        self.irradiance = torch.cat(irradiance) if irradiance else n.new_zeros((0, 3))
        self.specular = torch.cat(specular) if specular else n.new_zeros((0, levels, 3))  # (N, levels, 3)

    def rows(self, index: torch.Tensor | slice) -> "TabulatedLighting":
        """The tabulation of a subset of its pixels (`index` into them), without computing anything again."""
        part = object.__new__(TabulatedLighting)
        part.lighting, part.levels = self.lighting, self.levels
        part.irradiance, part.specular = self.irradiance[index], self.specular[index]
        part.count = part.irradiance.shape[0]
        return part

    def _check(self, rows: int) -> None:
        if rows != self.count:
            raise ValueError(f"this lighting was tabulated for {self.count} pixels, not {rows}")

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        self._check(normals.shape[0])
        return self.irradiance

    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        self._check(directions.shape[0])
        x = roughness.clamp(0.0, 1.0) * (self.levels - 1)
        below = x.detach().floor().long().clamp(max=self.levels - 2)
        t = (x - below.to(x.dtype))[:, None]
        rows = torch.arange(self.count, device=x.device)
        return self.specular[rows, below] * (1.0 - t) + self.specular[rows, below + 1] * t

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return self.lighting.brdf(n_dot_v, roughness)
