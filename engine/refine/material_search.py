"""Which roughness and metallic each part of the surface has: a search over material hypotheses in
the refinement, where the gradient does not go.

Why a search: the photometric gradient leaves roughness and metallic where the fit starts them
(README, "Lighting and materials": under the true light too). A dielectric's roughness matters
only through a 4% reflection, so lowering it barely changes the picture; raising its metallic
darkens the diffuse colour before the albedo has become the metal's reflectance, and at the
starting roughness a rough metal and a rough paint look alike. Only the pair (low roughness,
metal) explains a coloured mirror-like reflection, and the path there from (0.5, 0) is uphill.

The search looks at the whole of the evidence at once instead. Every photo pixel that sees the
object is rendered (no gradient) to its surface point and shading normal; points are binned into
small cells of the surface, so that a cell gathers the pixels of every view that sees it. For each
hypothesis (a roughness from a grid, metallic 0 or 1, and the field's own current pair) the
cell's albedo is solved in closed form (the shading is affine in the albedo: shade with albedo 0
and 1, least squares per channel over the cell's pixels) and the hypothesis is scored by the
photometric error it leaves, as the refinement's own PBR term measures it (L1 after the camera's
tone curve). Errors are summed over each cell's neighbours (3 x 3 x 3 cells) so that a choice reads
more than a handful of pixels, and the field's own pair is kept unless another is clearly better
(`margin`). A view-dependent reflection is what tells the hypotheses apart: across the views that
see a cell, a diffuse colour stays while a mirror's follows the environment.

The refinement then holds the field's roughness and metallic to the chosen pair (its material
prior's anchor) and lets the gradient go on from inside the right basin.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from lirm.engine.lighting.camera_response import display_to_radiance_torch, radiance_to_display_torch
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.model.occupancy_grid import OccupancyGrid

from .config import MaterialSearchSettings
from .ray_rendering import render_ray_batch, with_sdf_normals
from .refine_views import RefineViews

CLIPPED = 0.98  # a photo channel at or above this saw at least that much: no albedo is solved from it


@dataclass
class MaterialChoice:
    """Per surface cell, the chosen roughness and metallic, and where the field's own pair was kept."""

    radius: float
    cell: float
    side: int  # cells per axis of the dense grid over [-radius, radius]^3
    chosen: torch.Tensor  # (side^3,) bool: a hypothesis other than the field's own was chosen here
    roughness: torch.Tensor  # (side^3,)
    metallic: torch.Tensor  # (side^3,)
    shares: dict[str, float]  # share of the decided cells per outcome ("kept", "paint", "metal")

    def lookup(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(K, 3) -> roughness (K,), metallic (K,), chosen (K,) bool at the points' cells."""
        index = cell_index(points, self.radius, self.cell, self.side)
        return self.roughness.to(points)[index], self.metallic.to(points)[index], self.chosen.to(points.device)[index]

    def anchor(self, fallback):
        """A material anchor (points -> roughness, metallic) that gives the chosen pair where one was
        chosen and `fallback`'s (the anchor the fit had, or constants 0.5 and 0 when None) elsewhere."""

        @torch.no_grad()
        def anchored(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            roughness, metallic, chosen = self.lookup(points)
            if fallback is None:
                base_r, base_m = torch.full_like(roughness, 0.5), torch.zeros_like(metallic)
            else:
                base_r, base_m = fallback(points)
            return torch.where(chosen, roughness, base_r), torch.where(chosen, metallic, base_m)

        return anchored


def cell_index(points: torch.Tensor, radius: float, cell: float, side: int) -> torch.Tensor:
    ijk = ((points + radius) / cell).floor().long().clamp(0, side - 1)
    return (ijk[:, 0] * side + ijk[:, 1]) * side + ijk[:, 2]


@dataclass
class SurfacePixels:
    """The object pixels of every view at their surface: what a search scores hypotheses on."""

    points: torch.Tensor  # (P, 3)
    normal: torch.Tensor  # (P, 3) the shading normal (the SDF's)
    view: torch.Tensor  # (P, 3) surface -> eye
    colour: torch.Tensor  # (P, 3) the photo, display
    roughness: torch.Tensor  # (P,) the field's, now
    metallic: torch.Tensor  # (P,)


@torch.no_grad()
def surface_pixels(field, views: RefineViews, grid: OccupancyGrid | None, beta: float, coarse: int, fine: int,
                   settings: MaterialSearchSettings, generator: torch.Generator, device: torch.device) -> SurfacePixels:
    solid = (views.alphas > 0.99).nonzero()[:, 0]
    if solid.shape[0] > settings.max_pixels:
        solid = solid[torch.randperm(solid.shape[0], generator=generator)[: settings.max_pixels]]
    parts: dict[str, list[torch.Tensor]] = {k: [] for k in ("points", "normal", "view", "colour", "roughness", "metallic")}
    for begin in range(0, solid.shape[0], settings.chunk):
        index = solid[begin: begin + settings.chunk]
        origins, directions = views.origins[index].to(device), views.directions[index].to(device)
        render = render_ray_batch(field, origins, directions, grid, beta, coarse, fine, generator, materials=True)
        render = with_sdf_normals(field, render, origins, directions, shape_surface=False)
        hit = render.opacity > 0.5
        o = render.opacity[hit]
        parts["points"].append(origins[hit] + (render.depth[hit] / o)[:, None] * directions[hit])
        parts["normal"].append(F.normalize(render.normal[hit], dim=-1))
        parts["view"].append(-directions[hit])
        parts["colour"].append(views.colours[index].to(device)[hit])
        parts["roughness"].append((render.roughness[hit] / o).clamp(0.0, 1.0))
        parts["metallic"].append((render.metallic[hit] / o).clamp(0.0, 1.0))
    if not parts["points"]:  # no object pixel at all
        empty3, empty = torch.zeros(0, 3, device=device), torch.zeros(0, device=device)
        return SurfacePixels(empty3, empty3, empty3, empty3, empty, empty)
    return SurfacePixels(**{k: torch.cat(v) for k, v in parts.items()})


class _OneRoughness:
    """`shade`'s lighting interface with the irradiance and the prefiltered specular of one roughness
    computed once for the pixels: every hypothesis of that roughness (paint, metal; albedo 0, 1 and
    solved) shades from them, instead of summing the panorama's lobe again each time."""

    def __init__(self, lighting, irradiance: torch.Tensor, pixels: "SurfacePixels", roughness: float):
        self.lighting, self.irradiance = lighting, irradiance
        n, v = pixels.normal, pixels.view
        reflected = 2.0 * (n * v).sum(-1, keepdim=True) * n - v  # as `shade` forms it
        self.specular = lighting.prefiltered(reflected, torch.full_like(pixels.roughness, roughness))

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        return self.irradiance

    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return self.specular

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return self.lighting.brdf(n_dot_v, roughness)


def _solve_cell_albedo(lighting, pixels: SurfacePixels, roughness: torch.Tensor, metallic: torch.Tensor,
                       cells: torch.Tensor, count: int) -> torch.Tensor:
    """Per pixel, the albedo of its cell that shades closest (least squares in linear radiance, over
    the cell's unclipped pixels) to the cell's photo pixels under this hypothesis."""
    radiance = display_to_radiance_torch(pixels.colour.clamp(0.0, CLIPPED))
    terms = lambda albedo: shade(lighting, albedo, roughness, metallic, pixels.normal, pixels.view).radiance  # noqa: E731
    dark = terms(torch.zeros_like(radiance))
    gain = terms(torch.ones_like(radiance)) - dark
    usable = (pixels.colour < CLIPPED).to(radiance.dtype)
    numerator = torch.zeros(count, 3, dtype=radiance.dtype, device=radiance.device)
    denominator = torch.zeros_like(numerator)
    numerator.index_add_(0, cells, usable * gain * (radiance - dark))
    denominator.index_add_(0, cells, usable * gain * gain)
    albedo = (numerator / denominator.clamp(min=1e-8)).clamp(0.0, 1.0)
    return albedo[cells]


def _pixel_errors(lighting, pixels: SurfacePixels, roughness: torch.Tensor, metallic: torch.Tensor,
                  cells: torch.Tensor, count: int) -> torch.Tensor:
    """(P,) the PBR term's error of each pixel under a hypothesis, its cell's albedo solved for it.
    Clipped channels count only where the prediction stays below the clipping level."""
    albedo = _solve_cell_albedo(lighting, pixels, roughness, metallic, cells, count)
    shown = radiance_to_display_torch(shade(lighting, albedo, roughness, metallic, pixels.normal, pixels.view).radiance)
    difference = shown - pixels.colour
    clipped = pixels.colour >= CLIPPED
    difference = torch.where(clipped, (-difference).clamp(min=0.0), difference.abs())
    return difference.sum(-1)


def _neighbourhood(values: torch.Tensor, side: int) -> torch.Tensor:
    """(side^3,) -> the sum over each cell's 3 x 3 x 3 neighbours."""
    volume = values.view(1, 1, side, side, side)
    return F.conv3d(volume, torch.ones(1, 1, 3, 3, 3, dtype=values.dtype, device=values.device), padding=1).view(-1)


@torch.no_grad()
def choose_materials(lighting, pixels: SurfacePixels, radius: float, settings: MaterialSearchSettings) -> MaterialChoice:
    """The hypothesis with the least photometric error over each cell's neighbourhood; the field's
    own pair (the cell's mean roughness and metallic) first scaled by (1 - margin)."""
    side = max(int(round(2.0 * radius / (settings.cell * radius))), 1)
    cell = 2.0 * radius / side
    count = side**3
    device = pixels.points.device
    cells = cell_index(pixels.points, radius, cell, side)
    pixel_count = torch.zeros(count, device=device).index_add_(0, cells, torch.ones_like(cells, dtype=torch.float32))
    own_r = torch.zeros(count, device=device).index_add_(0, cells, pixels.roughness) / pixel_count.clamp(min=1)
    own_m = torch.zeros(count, device=device).index_add_(0, cells, pixels.metallic) / pixel_count.clamp(min=1)
    hypotheses = [(None, None)] + [(r, m) for r in settings.roughness for m in (0.0, 1.0)]
    irradiance = lighting.irradiance_over_pi(pixels.normal)
    sums, terms = [], None
    for r, m in hypotheses:
        if r is None:
            roughness, metallic, terms = own_r[cells], own_m[cells], lighting
        else:
            if m == 0.0:  # a new roughness: its specular once, for the paint and the metal
                terms = _OneRoughness(lighting, irradiance, pixels, r)
            roughness, metallic = torch.full_like(pixels.roughness, r), torch.full_like(pixels.metallic, m)
        errors = _pixel_errors(terms, pixels, roughness, metallic, cells, count)
        sums.append(_neighbourhood(torch.zeros(count, device=device).index_add_(0, cells, errors), side))
    sums = torch.stack(sums)
    sums[0] *= 1.0 - settings.margin
    best = sums.argmin(dim=0)
    support = _neighbourhood(pixel_count, side)
    seen = pixel_count > 0
    best = torch.where(support >= settings.min_pixels, best, torch.zeros_like(best))
    table_r = torch.tensor([0.5] + [r for r, _ in hypotheses[1:]], device=device)  # index 0 (the field's own) is not read
    table_m = torch.tensor([0.0] + [m for _, m in hypotheses[1:]], device=device)
    chosen = (best > 0) & seen
    roughness = torch.where(chosen, table_r[best], own_r)
    metallic = torch.where(chosen, table_m[best], own_m)
    decided = int(seen.sum())
    metal = int((chosen & (table_m[best] > 0.5)).sum())
    paint = int(chosen.sum()) - metal
    shares = {"kept": (decided - metal - paint) / max(decided, 1), "paint": paint / max(decided, 1),
              "metal": metal / max(decided, 1)}
    return MaterialChoice(radius, cell, side, chosen.cpu(), roughness.cpu(), metallic.cpu(), shares)


def search_materials(field, views: RefineViews, grid: OccupancyGrid | None, lighting, beta: float, coarse: int, fine: int,
                     settings: MaterialSearchSettings, generator: torch.Generator, device: torch.device) -> MaterialChoice:
    pixels = surface_pixels(field, views, grid, beta, coarse, fine, settings, generator, device)
    return choose_materials(lighting, pixels, float(field.radius), settings)
