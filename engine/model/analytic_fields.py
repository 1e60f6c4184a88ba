"""Analytic fields with the decoded field's interface: exact SDFs and known material patterns.

They check the volume renderer (and later the exporter) independently of learning: silhouettes,
depths and normals have closed forms, and the material patterns make swapped channels visible
(roughness and metallic vary along different axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F

from .field import FieldSample


@dataclass(frozen=True)
class MaterialPattern:
    """albedo: checker of two colours (cells of `checker` world units); roughness ramps along x,
    metallic is 1 on the +y half and 0 on the -y half (sharp, so a swap with roughness shows)."""

    colour_a: tuple[float, float, float] = (0.8, 0.2, 0.1)
    colour_b: tuple[float, float, float] = (0.1, 0.3, 0.8)
    checker: float = 0.25
    roughness_range: tuple[float, float] = (0.2, 0.9)

    def albedo(self, p: torch.Tensor) -> torch.Tensor:
        cells = torch.floor(p / self.checker).sum(-1)
        odd = (torch.remainder(cells, 2.0) > 0.5).unsqueeze(-1)
        a = torch.tensor(self.colour_a, dtype=p.dtype, device=p.device)
        b = torch.tensor(self.colour_b, dtype=p.dtype, device=p.device)
        return torch.where(odd, b, a).expand(*p.shape[:-1], 3)

    def roughness(self, p: torch.Tensor, radius: float) -> torch.Tensor:
        lo, hi = self.roughness_range
        return lo + (hi - lo) * (p[..., 0] / radius * 0.5 + 0.5).clamp(0.0, 1.0)

    def metallic(self, p: torch.Tensor) -> torch.Tensor:
        return (p[..., 1] >= 0).to(p.dtype)


class AnalyticField:
    """Base: subclasses give `sdf`; colour is the albedo (an emissive, view-independent field)."""

    def __init__(self, radius: float = 1.0, pattern: MaterialPattern = MaterialPattern(), normal_eps: float = 1e-3):
        self.radius = radius
        self.pattern = pattern
        self.normal_eps = normal_eps

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def gradient(self, points: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def sample(self, points: torch.Tensor, view_dirs: torch.Tensor | None = None) -> FieldSample:
        albedo = self.pattern.albedo(points)
        return FieldSample(sdf=self.sdf(points), albedo=albedo, roughness=self.pattern.roughness(points, self.radius),
                           metallic=self.pattern.metallic(points), normal=F.normalize(self.gradient(points), dim=-1),
                           colour=None if view_dirs is None else albedo)


class SphereField(AnalyticField):
    def __init__(self, sphere_radius: float = 0.5, center: tuple[float, float, float] = (0.0, 0.0, 0.0), **kwargs):
        super().__init__(**kwargs)
        self.sphere_radius = sphere_radius
        self.center = torch.tensor(center, dtype=torch.float32)

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return (points - self.center.to(points)).norm(dim=-1) - self.sphere_radius

    def gradient(self, points: torch.Tensor) -> torch.Tensor:
        return points - self.center.to(points)


class BoxField(AnalyticField):
    """An axis-aligned box of half extents `half` (exact Euclidean SDF, outside and inside)."""

    def __init__(self, half: tuple[float, float, float] = (0.4, 0.3, 0.2), **kwargs):
        super().__init__(**kwargs)
        self.half = torch.tensor(half, dtype=torch.float32)

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        q = points.abs() - self.half.to(points)
        return q.clamp(min=0.0).norm(dim=-1) + q.max(dim=-1).values.clamp(max=0.0)

    def gradient(self, points: torch.Tensor) -> torch.Tensor:
        q = points.abs() - self.half.to(points)
        outside = q.clamp(min=0.0)
        inside_axis = F.one_hot(q.argmax(dim=-1), 3).to(points.dtype)
        g = torch.where((q > 0).any(dim=-1, keepdim=True), outside, inside_axis)
        return g * torch.sign(points + 1e-12)


def box_ray_hit(origins: torch.Tensor, directions: torch.Tensor, half: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Slab test: (distance to the box's first hit, hit mask) for rays against the box [-half, half]."""
    inv = 1.0 / torch.where(directions.abs() < 1e-12, torch.full_like(directions, 1e-12), directions)
    t0, t1 = (-half - origins) * inv, (half - origins) * inv
    t_near = torch.minimum(t0, t1).max(dim=-1).values
    t_far = torch.maximum(t0, t1).min(dim=-1).values
    return t_near, (t_far >= t_near) & (t_far > 0)


def sphere_ray_hit(origins: torch.Tensor, directions: torch.Tensor, radius: float) -> tuple[torch.Tensor, torch.Tensor]:
    b = (origins * directions).sum(-1)
    disc = b * b - ((origins * origins).sum(-1) - radius * radius)
    return -b - torch.sqrt(disc.clamp(min=0.0)), disc > 0

