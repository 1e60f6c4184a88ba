"""VolSDF volume rendering of a field (paper eqs. 9 and 17), in pure torch.

Rays are clipped to the field's bounding sphere of radius R and sampled at `samples_per_ray` evenly
spaced depths (jittered within their bins when training). The density is VolSDF's
sigma = (1/beta) Psi_beta(-s); alpha = 1 - exp(-sigma delta); weights w = alpha T. Colour, albedo,
roughness, metallic, the MLP normal, the numerical normal (central differences of the SDF, paper
§3.4), depth and opacity are composited with the same weights.

An occupancy grid (occupancy_grid.py) prunes the samples in empty space: only the kept samples are
evaluated, packed into one list, and composited back with index_add, so skipping saves the field's
cost and not just the compositing. Works on any field with `sdf(points)`, `sample(points, dirs)`,
`normal_eps` and `config.radius`-like `radius`: the decoded LIRM field or an analytic one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dataclass_field, replace

import numpy as np
import torch
import torch.nn.functional as F

from lirm.engine.cameras import Camera

from .field import volsdf_density
from .occupancy_grid import OccupancyConfig, OccupancyGrid

# Channels of the composited maps. "colour" is over the background; the others are premultiplied by opacity.
CHANNELS = {"colour": 3, "albedo": 3, "roughness": 1, "metallic": 1, "normal": 3, "normal_numerical": 3}


@dataclass(frozen=True)
class VolumeRenderConfig:
    samples_per_ray: int = 128
    beta: float = 1.0 / 250.0  # the end of training's 1/beta schedule (supplementary table)
    chunk_rays: int = 2048  # rays per batch when rendering whole cameras
    background: float = 1.0  # white, like the masked input images
    stratified: bool = False  # jitter each sample within its bin (training)
    numerical_normals: bool = True


FITTED_SPACING_IN_BETAS = 5.0  # as_fitted's sample spacing at most this many betas: the density's step within a few samples


def as_fitted(config: VolumeRenderConfig, field, dense: bool = True) -> VolumeRenderConfig:
    """`config` at the beta `field` was fitted at when it carries one (a refined field's
    Field.fitted_beta; the refinement ends sharper than the model's 1/250), else unchanged. Its
    density was fitted at that sharpness: rendered softer, the surface spreads outward and the
    colours blur. With `dense`, also enough evenly spaced samples that the spacing stays within
    FITTED_SPACING_IN_BETAS betas: sparser, a sharp density is read up to a sample inside the surface
    (4 refined synthetic fields from the output views, PSNR / albedo PSNR: 26.17 / 17.35 at 1/250 and
    96 samples, 27.02 / 17.17 at the fitted 1/500 and 96, 27.13 / 17.36 at 1/500 and 192; README,
    "The refined field rendered as fitted"). An interactive preview passes dense=False."""
    beta = getattr(field, "fitted_beta", None)
    if beta is None:
        return config
    samples = config.samples_per_ray
    if dense:
        samples = max(samples, math.ceil(2.0 * float(field.radius) / (FITTED_SPACING_IN_BETAS * float(beta))))
    return replace(config, beta=float(beta), samples_per_ray=samples)


def fitted_render(field, config: VolumeRenderConfig, occupancy: OccupancyConfig,
                  dense: bool = True) -> tuple[VolumeRenderConfig, OccupancyGrid]:
    """What rendering `field` whole needs: `config` as fitted (as_fitted) and the occupancy grid
    built at its beta and sample step."""
    config = as_fitted(config, field, dense)
    grid = OccupancyGrid.build(field, field.radius, config.beta, 2.0 * field.radius / config.samples_per_ray, occupancy)
    return config, grid


@dataclass
class RenderStats:
    samples_total: int = 0  # samples on rays that hit the bounding sphere
    samples_evaluated: int = 0  # of those, the ones the occupancy grid kept

    @property
    def skipped_fraction(self) -> float:
        return 1.0 - self.samples_evaluated / max(self.samples_total, 1)


@dataclass
class VolumeImages:
    """A camera's rendering as (H, W, C) float32 arrays; depth is camera-space z (OpenCV), 0 where empty."""

    maps: dict[str, np.ndarray]
    stats: RenderStats = dataclass_field(default_factory=RenderStats)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.maps[name]


def sphere_interval(origins: torch.Tensor, directions: torch.Tensor, radius: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Where unit-direction rays enter and leave the sphere |x| = radius: (near, far, hit)."""
    b = (origins * directions).sum(-1)
    c = (origins * origins).sum(-1) - radius * radius
    disc = b * b - c
    root = torch.sqrt(disc.clamp(min=0.0))
    near = (-b - root).clamp(min=0.0)
    far = -b + root
    hit = (disc > 0) & (far > near)
    return near, torch.where(hit, far, near), hit


def render_rays(field, origins: torch.Tensor, directions: torch.Tensor, config: VolumeRenderConfig = VolumeRenderConfig(),
                grid: OccupancyGrid | None = None, stats: RenderStats | None = None,
                generator: torch.Generator | None = None) -> dict[str, torch.Tensor]:
    """origins, directions (N, 3) with unit directions -> maps (N, C) plus "opacity" and "distance" (N, 1).

    Differentiable with respect to the field (training renders ray batches through this)."""
    n, s = origins.shape[0], config.samples_per_ray
    device = origins.device
    near, far, hit = sphere_interval(origins, directions, field.radius)
    bins = torch.arange(s, device=device, dtype=origins.dtype)
    offsets = torch.rand(n, s, device=device, generator=generator) if config.stratified else torch.full((n, s), 0.5, device=device)
    delta = ((far - near) / s)[:, None]  # (N, 1)
    t = near[:, None] + (bins[None] + offsets) * delta  # (N, S)
    points = origins[:, None] + t[..., None] * directions[:, None]  # (N, S, 3)

    keep = hit[:, None].expand(n, s)
    if grid is not None:
        keep = keep & grid.lookup(points)
    if stats is not None:
        stats.samples_total += int(hit.sum()) * s
        stats.samples_evaluated += int(keep.sum())
    kept_index = keep.nonzero(as_tuple=True)  # (ray, sample) of every kept sample
    ray_index = kept_index[0]
    kept_points = points[keep]
    kept_dirs = directions[ray_index]

    out = {name: torch.zeros(n, c, device=device, dtype=origins.dtype) for name, c in CHANNELS.items()}
    out["opacity"] = torch.zeros(n, 1, device=device, dtype=origins.dtype)
    out["distance"] = torch.zeros(n, 1, device=device, dtype=origins.dtype)
    if kept_points.shape[0]:
        sample = field.sample(kept_points[None], kept_dirs[None])
        sigma = torch.zeros(n, s, device=device, dtype=origins.dtype)
        sigma = sigma.index_put(kept_index, volsdf_density(sample.sdf[0], config.beta) / config.beta)
        alpha = 1.0 - torch.exp(-sigma * delta)
        transmittance = torch.cumprod(torch.cat([torch.ones_like(alpha[:, :1]), 1.0 - alpha[:, :-1] + 1e-10], dim=1), dim=1)
        w = (alpha * transmittance)[keep][:, None]  # (K, 1)
        values = {"albedo": sample.albedo[0], "roughness": sample.roughness[0][:, None], "metallic": sample.metallic[0][:, None],
                  "normal": sample.normal[0], "colour": sample.colour[0]}
        if config.numerical_normals:
            values["normal_numerical"] = numerical_normals(field, kept_points)
        for name, value in values.items():
            out[name] = out[name].index_add(0, ray_index, w * value)
        out["opacity"] = out["opacity"].index_add(0, ray_index, w)
        out["distance"] = out["distance"].index_add(0, ray_index, w * t[keep][:, None])
    out["colour"] = out["colour"] + (1.0 - out["opacity"]) * config.background
    return out


def numerical_normals(field, points: torch.Tensor) -> torch.Tensor:
    """(K, 3) -> (K, 3) unit gradient of the SDF by central differences at `field.normal_eps`
    (2 hexa-plane voxels for the LIRM field, paper §3.4)."""
    eps = field.normal_eps
    offsets = torch.eye(3, device=points.device, dtype=points.dtype) * eps
    probes = torch.cat([points[:, None] + offsets[None], points[:, None] - offsets[None]], dim=1)  # (K, 6, 3)
    s = field.sdf(probes.reshape(1, -1, 3))[0].view(-1, 6)
    return F.normalize(s[:, :3] - s[:, 3:], dim=-1)


@torch.no_grad()
def render_camera(field, camera: Camera, config: VolumeRenderConfig = VolumeRenderConfig(), grid: OccupancyGrid | None = None,
                  device: torch.device | str = "cpu") -> VolumeImages:
    """Every pixel of `camera`, in chunks of rays. Maps: colour (over the background), albedo,
    roughness, metallic and normals (divided by opacity where it is > 0), depth (camera z), opacity."""
    origins, directions = camera.pixel_rays()
    h, w = camera.height, camera.width
    o = torch.as_tensor(origins.reshape(-1, 3), dtype=torch.float32, device=device)
    d = torch.as_tensor(directions.reshape(-1, 3), dtype=torch.float32, device=device)
    stats = RenderStats()
    pieces: dict[str, list[torch.Tensor]] = {}
    for start in range(0, o.shape[0], config.chunk_rays):
        chunk = render_rays(field, o[start:start + config.chunk_rays], d[start:start + config.chunk_rays], config, grid, stats)
        for name, value in chunk.items():
            pieces.setdefault(name, []).append(value.cpu())
    maps = {name: torch.cat(parts).numpy().reshape(h, w, -1) for name, parts in pieces.items()}
    opacity = maps["opacity"]
    covered = np.maximum(opacity, 1e-8)
    for name in ("albedo", "roughness", "metallic", "normal", "normal_numerical", "distance"):
        maps[name] = np.where(opacity > 1e-4, maps[name] / covered, 0.0).astype(np.float32)
    for name in ("normal", "normal_numerical"):
        norm = np.linalg.norm(maps[name], axis=-1, keepdims=True)
        maps[name] = np.where(norm > 1e-8, maps[name] / np.maximum(norm, 1e-8), 0.0).astype(np.float32)
    # distance along the unit ray -> camera-space z, the renderer's depth convention
    forward = camera.c2w[:3, 2]
    cos = (directions @ forward).reshape(h, w, 1)
    maps["depth"] = (maps.pop("distance") * cos).astype(np.float32)
    for name in ("roughness", "metallic", "opacity", "depth"):
        maps[name] = maps[name][..., 0]
    return VolumeImages(maps, stats)
