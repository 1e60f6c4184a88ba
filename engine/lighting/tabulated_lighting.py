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

The BRDF table's (A, B) are tabulated too, per pixel at its own N.V and at every row of the table
(BRDF_ROWS, the rows of panorama_lighting.brdf_table): for fixed N.V a bilinear read of the table is
linear in roughness between its row centres, so reading these per-pixel rows linearly is the same
lookup. With the N.V and Schlick's weight kept as well, `shade` (this class's own) does per step
only what the materials change: two gathers and the split-sum mix. With the texture fit's sparse
reads, a step at the demo's 1.2M sub-samples went from 0.57-0.70 s to 0.45 s (README, "The texture
fit's pace").

It also keeps `split_sum_shading.shade`'s lighting interface; the directions `shade` passes are
ignored (they are the tabulated ones), so it must be called on exactly the pixels it was built for.
"""

from __future__ import annotations

import numpy as np
import torch

from lirm.renderer.environment import Environment

from .panorama_lighting import PanoramaLighting
from .split_sum_shading import ShadingTerms, equirect_lookup, fresnel_weight, mix_split_sum

# Directions per panorama texel side on the grid a panorama's terms are computed on first.
PANORAMA_GRID_FACTOR = 8
# Roughness rows the BRDF table is tabulated at, at (i + 0.5) / rows: panorama_lighting.brdf_table's
# size, so the fitted lighting's table is read exactly (another lighting's table of other rows is
# interpolated between these).
BRDF_ROWS = 32


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
        cos = (n * v).sum(-1)
        reflected = 2.0 * cos[:, None] * n - v  # GLSL reflect(-v, n), as `shade` takes it
        self.n_dot_v = cos.clamp(1e-4, 1.0)  # as `shade` clamps it
        self.fresnel = fresnel_weight(self.n_dot_v)
        roughness_levels = torch.linspace(0.0, 1.0, levels, dtype=n.dtype, device=n.device)
        irradiance, specular, brdf = [], [], []
        row_roughness = (torch.arange(BRDF_ROWS, dtype=n.dtype, device=n.device) + 0.5) / BRDF_ROWS
        with torch.no_grad():
            grid = _OnDirectionGrid(lighting, roughness_levels) if isinstance(lighting, PanoramaLighting) else None
            for start in range(0, self.count, chunk):
                part_n, part_r = n[start:start + chunk], reflected[start:start + chunk]
                part_cos = self.n_dot_v[start:start + chunk]
                # every row at once: one lookup of the table for (pixel, row) pairs, pixel-major
                pairs_cos = part_cos.repeat_interleave(BRDF_ROWS)
                brdf.append(lighting.brdf(pairs_cos, row_roughness.repeat(part_cos.shape[0])).reshape(-1, BRDF_ROWS, 2))
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
        self.brdf_rows = torch.cat(brdf) if brdf else n.new_zeros((0, BRDF_ROWS, 2))  # (N, BRDF_ROWS, 2)

    def rows(self, index: torch.Tensor | slice) -> "TabulatedLighting":
        """The tabulation of a subset of its pixels (`index` into them), without computing anything again."""
        part = object.__new__(TabulatedLighting)
        part.lighting, part.levels = self.lighting, self.levels
        # contiguous copies: the gathers read them as flat tables
        part.irradiance, part.specular = self.irradiance[index].contiguous(), self.specular[index].contiguous()
        part.brdf_rows, part.n_dot_v = self.brdf_rows[index].contiguous(), self.n_dot_v[index].contiguous()
        part.fresnel = self.fresnel[index].contiguous()
        part.count = part.irradiance.shape[0]
        return part

    def pooled(self, group: int) -> "TabulatedLighting":
        """Each run of `group` consecutive pixels as one: the mean of their terms (a photo pixel's
        footprint shaded once, as the texture fit's "pooled" footprint does)."""
        if group < 1 or self.count % group:
            raise ValueError(f"{self.count} pixels do not make whole runs of {group}")
        part = object.__new__(TabulatedLighting)
        part.lighting, part.levels, part.count = self.lighting, self.levels, self.count // group
        mean = lambda t: t.reshape(part.count, group, *t.shape[1:]).mean(1)  # noqa: E731
        part.irradiance, part.specular, part.brdf_rows = mean(self.irradiance), mean(self.specular), mean(self.brdf_rows)
        part.n_dot_v, part.fresnel = mean(self.n_dot_v), mean(self.fresnel)
        return part

    def _check(self, rows: int) -> None:
        if rows != self.count:
            raise ValueError(f"this lighting was tabulated for {self.count} pixels, not {rows}")

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        self._check(normals.shape[0])
        return self.irradiance

    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        self._check(directions.shape[0])
        return _between_rows(self.specular, roughness.clamp(0.0, 1.0) * (self.levels - 1))

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        self._check(n_dot_v.shape[0])
        return _between_rows(self.brdf_rows, roughness * BRDF_ROWS - 0.5)

    def shade(self, albedo: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor,
              multiple_scattering: bool = True) -> ShadingTerms:
        """split_sum_shading.shade at the tabulated pixels (the same model and values), computing only
        what depends on the materials."""
        self._check(albedo.shape[0])
        roughness = roughness.clamp(0.0, 1.0)
        metallic = metallic.clamp(0.0, 1.0)
        ab = _between_rows(self.brdf_rows, roughness * BRDF_ROWS - 0.5)
        specular = _between_rows(self.specular, roughness * (self.levels - 1))
        return mix_split_sum(albedo, roughness, metallic, self.fresnel, ab, specular, self.irradiance, multiple_scattering)


def _between_rows(table: torch.Tensor, position: torch.Tensor) -> torch.Tensor:
    """(N, C): each pixel's (N, R, C) rows read linearly at its fractional row `position` (N,), clamped
    to the first and last rows (GL_LINEAR's clamp-to-edge); differentiable by autograd."""
    return linear_row_read(table, position[:, None])[0]


def linear_row_read(table: torch.Tensor, position: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Each sample's (M, R, C) rows read linearly at its fractional row `position` (M, 1), clamped to
    the first and last rows, and the read's slope in `position` (zero where clamped): one gather of
    both neighbouring rows, through a view of the table whose row i holds rows i and i + 1."""
    samples, rows, channels = table.shape
    x = position.clamp(0.0, rows - 1.0)
    below = x.floor().long().clamp(max=rows - 2)
    flat = table.reshape(-1)
    pairs = flat.as_strided((flat.numel() // channels - 1, 2 * channels), (channels, 1))
    first = torch.arange(samples, device=table.device) * rows + below[:, 0]
    both = pairs.index_select(0, first)
    low, high = both[:, :channels], both[:, channels:]
    step = high - low
    value = torch.addcmul(low, step, x - below.to(x.dtype))
    inside = (position >= 0.0) & (position <= rows - 1.0)  # torch's clamp passes the gradient at its bounds
    return value, step * inside
