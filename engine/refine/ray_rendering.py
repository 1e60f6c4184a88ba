"""Differentiable rendering of a batch of rays for the refinement: VolSDF, as the shared volume
renderer (model/volume_renderer.py) composites it, with samples placed where they matter.

- Samples are taken only inside the occupancy grid (the visual hull of the masks, slightly dilated):
  every other point of the bounding sphere is known to be empty.
- A coarse pass (SDF only, no gradient) finds where each ray crosses the surface; the fine samples
  are drawn around it by inverse transform sampling of the coarse weights (importance sampling),
  with a floor over the whole occupied interval so that surfaces the current SDF misses still get
  samples and can appear.
- The field is evaluated with gradients at the occupied coarse and the fine samples together, sorted
  along the ray; each sample's density holds over the distance to the next (VolSDF's quadrature).
- The SDF is read at all of them; the other heads (colour, albedo, materials, normal) only at the
  samples whose weight is above APPEARANCE_WEIGHT, from the same plane features.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch

from lirm.engine.model.field import volsdf_density
from lirm.engine.model.occupancy_grid import OccupancyGrid
from lirm.engine.model.volume_renderer import sphere_interval

from .config import APPEARANCE_WEIGHT

UNIFORM_FLOOR = 0.05  # share of the fine-sample density spread over the whole occupied part of the ray


@dataclass
class RayBatchRender:
    colour: torch.Tensor  # (N, 3) over the background
    opacity: torch.Tensor  # (N,)
    albedo: torch.Tensor  # (N, 3) premultiplied by opacity
    roughness: torch.Tensor | None  # (N,) premultiplied; None when rendered without materials
    metallic: torch.Tensor | None  # (N,) premultiplied
    normal: torch.Tensor  # (N, 3) the MLP normal, premultiplied
    depth: torch.Tensor  # (N,) the distance along the ray, premultiplied (detached: where the photos see a surface)
    surface_points: torch.Tensor  # (K, 3) detached fine samples with weight: where the eikonal term looks
    samples: int  # field evaluations with gradient in this batch
    # (N,) the slope variance of the surface's normal over each ray's pixel (footprint_roughness.py),
    # 0 where the ray meets no surface; None: not measured (the shading reads each ray's one normal).
    normal_spread: torch.Tensor | None = None


def render_ray_batch(field, origins: torch.Tensor, directions: torch.Tensor, grid: OccupancyGrid | None, beta: float,
                     coarse_samples: int, fine_samples: int, generator: torch.Generator | None = None,
                     background: float = 1.0, materials: bool = True, prune_weight: float = APPEARANCE_WEIGHT) -> RayBatchRender:
    """`materials=False`: roughness and metallic are not rendered (None), for losses that do not read them.
    `prune_weight`: samples of less weight are left out of the colour and the materials (their SDF
    still shapes the opacity and the transmittance); 0 keeps every sample."""
    n, device = origins.shape[0], origins.device
    near, far, hit = sphere_interval(origins, directions, field.radius)
    span = (far - near)[:, None]
    # Coarse: stratified in the sphere interval, kept inside the occupancy grid.
    bins = torch.arange(coarse_samples, device=device, dtype=origins.dtype)
    jitter = torch.rand(n, coarse_samples, device=device, generator=generator)
    t_coarse = near[:, None] + (bins[None] + jitter) / coarse_samples * span
    occupied_coarse = _occupied(origins, directions, t_coarse, hit, grid)
    with torch.no_grad():
        sdf = torch.full((n, coarse_samples), 1e3, device=device, dtype=origins.dtype)
        if occupied_coarse.any():
            points = origins[:, None] + t_coarse[..., None] * directions[:, None]
            sdf[occupied_coarse] = field.sdf(points[occupied_coarse][None])[0]
        t_fine = _importance_samples(t_coarse, sdf, occupied_coarse, near, far, beta, fine_samples, generator)
    occupied_fine = _occupied(origins, directions, t_fine, hit, grid)
    t_all, order = torch.sort(torch.cat([t_coarse, t_fine], dim=1), dim=1)
    occupied = torch.gather(torch.cat([occupied_coarse, occupied_fine], dim=1), 1, order)
    delta = torch.cat([t_all[:, 1:] - t_all[:, :-1], (far[:, None] - t_all[:, -1:]).clamp(min=1e-4)], dim=1)

    index = occupied.nonzero(as_tuple=True)
    ray_index = index[0]
    points = origins[ray_index] + t_all[occupied][:, None] * directions[ray_index]
    zeros3 = torch.zeros(n, 3, device=device, dtype=origins.dtype)
    zeros1 = torch.zeros(n, device=device, dtype=origins.dtype)
    if points.shape[0] == 0:
        return RayBatchRender(zeros3 + background, zeros1, zeros3, zeros1, zeros1, zeros3, zeros1, points.detach(), 0)
    view_dirs = directions[ray_index]
    split = hasattr(field, "sdf_and_features") and prune_weight > 0.0
    if split:
        sdf, features = field.sdf_and_features(points[None])
        sdf = sdf[0]
    else:
        sample = field.sample(points[None], view_dirs[None], materials=materials)
        sdf = sample.sdf[0]
    sigma = torch.zeros(n, t_all.shape[1], device=device, dtype=origins.dtype)
    sigma = sigma.index_put(index, volsdf_density(sdf, beta) / beta)
    alpha = 1.0 - torch.exp(-sigma * delta)
    transmittance = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1.0 - alpha[:, :-1] + 1e-10], dim=1), dim=1)
    weights = (alpha * transmittance)[occupied]  # (K,)
    opacity = zeros1.index_add(0, ray_index, weights)
    depth = zeros1.index_add(0, ray_index, weights.detach() * t_all[occupied])
    near_surface = points.detach()[weights.detach() > 1e-3]
    if split:
        # The appearance heads only where a sample carries weight: behind the first surface and far in
        # front of it a sample's weight is ~0 (70% of the samples once 1/beta is sharp), and reading
        # six heads there is most of a step's cost for nothing the composite would show.
        kept = weights.detach() > prune_weight
        if not bool(kept.any()):
            kept = weights.detach() >= weights.detach().max()
        sample = field.sample_features(features[:, kept], points[kept][None], view_dirs[kept][None], materials=materials,
                                       sdf=sdf[kept][None])
        ray_index, weights = ray_index[kept], weights[kept]
    w = weights[:, None]
    composite = lambda values: zeros3.index_add(0, ray_index, w * values)  # noqa: E731
    composite1 = lambda values: zeros1.index_add(0, ray_index, weights * values)  # noqa: E731
    # Over the background by the opacity of the samples composited (all of them unless pruned), so
    # that a pruned sample is absent from the colour rather than black; the mask term reads them all.
    colour = composite(sample.colour[0]) + (1.0 - composite1(torch.ones_like(weights)))[:, None] * background
    roughness = composite1(sample.roughness[0]) if materials else None
    metallic = composite1(sample.metallic[0]) if materials else None
    return RayBatchRender(colour, opacity, composite(sample.albedo[0]), roughness, metallic, composite(sample.normal[0]),
                          depth, near_surface, int(points.shape[0]))


def with_sdf_normals(field, render: RayBatchRender, origins: torch.Tensor, directions: torch.Tensor,
                     shape_surface: bool = True, pixel_angles: torch.Tensor | None = None) -> RayBatchRender:
    """The batch with its shading normal replaced by the SDF's own gradient (central differences at
    the field's `normal_eps`, as the export's normal map stores it) at each ray's expected surface
    point, where the ray is mostly opaque; elsewhere the head's normal stays. The gradient reaches
    the SDF, so the shading can shape the surface too; with `shape_surface` False it does not (the
    normal is read as it is, and only the materials and the lighting answer to the shading). With
    `pixel_angles` (N,), also the spread of the normal over each ray's pixel (footprint_roughness.py)."""
    from lirm.engine.model.volume_renderer import numerical_normals

    from .footprint_roughness import footprint_normal_spread

    opacity = render.opacity.detach()
    hit = opacity > 0.5
    if not bool(hit.any()):
        return render
    distance = render.depth[hit] / opacity[hit]
    points = origins[hit] + distance[:, None] * directions[hit]
    normal = render.normal.clone()
    with torch.set_grad_enabled(shape_surface and torch.is_grad_enabled()):
        surface_normal = numerical_normals(field, points)
    normal[hit] = surface_normal * render.opacity[hit, None]  # premultiplied, like the head's
    spread = None
    if pixel_angles is not None:
        spread = torch.zeros_like(opacity)
        spread[hit] = footprint_normal_spread(field, points, surface_normal.detach(), directions[hit], distance, pixel_angles[hit])
    return replace(render, normal=normal, normal_spread=spread)


@torch.no_grad()
def rays_meeting_grid(origins: torch.Tensor, directions: torch.Tensor, grid: OccupancyGrid, radius: float,
                      steps: int = 192, chunk: int = 16384) -> torch.Tensor:
    """(N,) bool: which rays pass through an occupied voxel of `grid` (checked at `steps` points
    along each ray's chord of the bounding sphere, closer than a voxel). A ray that meets none is
    rendered empty whatever the field holds: it has no gradient to give."""
    device = grid.occupied.device
    out = torch.zeros(origins.shape[0], dtype=torch.bool)
    fractions = (torch.arange(steps, dtype=origins.dtype, device=device) + 0.5) / steps
    for start in range(0, origins.shape[0], chunk):
        o, d = origins[start:start + chunk].to(device), directions[start:start + chunk].to(device)
        near, far, hit = sphere_interval(o, d, radius)
        t = near[:, None] + fractions[None] * (far - near)[:, None]
        out[start:start + chunk] = _occupied(o, d, t, hit, grid).any(dim=1).cpu()
    return out


def _occupied(origins, directions, t, hit, grid: OccupancyGrid | None) -> torch.Tensor:
    keep = hit[:, None].expand_as(t)
    if grid is None:
        return keep.clone()
    points = origins[:, None] + t[..., None] * directions[:, None]
    return keep & grid.lookup(points)


def _importance_samples(t_coarse, sdf, occupied, near, far, beta: float, count: int, generator) -> torch.Tensor:
    """Inverse transform sampling of `count` depths per ray from the coarse pass's weights.

    The weight of the interval between two coarse samples is the opacity VolSDF gives it at the mean
    of their SDF values, times the transmittance before it; the coarse spacing is usually wider than
    beta, so the density there is taken with beta no smaller than half a coarse step, which keeps a
    crossing between two samples visible."""
    n, s = t_coarse.shape
    edges = torch.cat([near[:, None], 0.5 * (t_coarse[:, 1:] + t_coarse[:, :-1]), far[:, None]], dim=1)  # (N, S+1)
    width = (edges[:, 1:] - edges[:, :-1]).clamp(min=0.0)  # (N, S): the bin around each coarse sample
    step = float(width.max()) if width.numel() else 1.0
    soft_beta = max(beta, 0.5 * step / 2.0)
    mean_sdf = torch.cat([0.5 * (sdf[:, :-1] + sdf[:, 1:]), sdf[:, -1:]], dim=1)
    sigma = torch.where(occupied, volsdf_density(torch.minimum(sdf, mean_sdf), soft_beta) / soft_beta, torch.zeros_like(sdf))
    alpha = 1.0 - torch.exp(-sigma * width)
    transmittance = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1.0 - alpha[:, :-1] + 1e-10], dim=1), dim=1)
    weights = alpha * transmittance
    floor = occupied.to(weights.dtype) * width
    weights = weights / weights.sum(1, keepdim=True).clamp(min=1e-8)
    floor = floor / floor.sum(1, keepdim=True).clamp(min=1e-8)
    pdf = (1.0 - UNIFORM_FLOOR) * weights + UNIFORM_FLOOR * floor
    empty = pdf.sum(1, keepdim=True) < 1e-6
    pdf = torch.where(empty, width / width.sum(1, keepdim=True).clamp(min=1e-8), pdf) + 1e-8
    cdf = torch.cumsum(pdf / pdf.sum(1, keepdim=True), dim=1)
    cdf = torch.cat([torch.zeros_like(cdf[:, :1]), cdf], dim=1)  # (N, S+1), at the edges
    u = (torch.arange(count, device=t_coarse.device, dtype=t_coarse.dtype)[None]
         + torch.rand(n, count, device=t_coarse.device, generator=generator)) / count
    upper = torch.searchsorted(cdf.contiguous(), u.contiguous(), right=True).clamp(1, s)
    lower = upper - 1
    c0, c1 = torch.gather(cdf, 1, lower), torch.gather(cdf, 1, upper)
    e0, e1 = torch.gather(edges, 1, lower), torch.gather(edges, 1, upper)
    frac = ((u - c0) / (c1 - c0).clamp(min=1e-8)).clamp(0.0, 1.0)
    return e0 + frac * (e1 - e0)
