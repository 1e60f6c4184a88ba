"""The decoded field (paper eqs. 8-16): SDF with the s_bias prior, PBR materials, normals and colour.

Separate small MLPs (2-3 hidden layers, 32 wide) read the concatenated plane features f. Colour is
MLP_c(f, f_d) with f_d from the NDE panoramas at the reflection direction ("nde"), or MLP_c(f)
("diff"). The density is VolSDF's Laplace CDF of -s with scale beta (eq. 9).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from .config import LIRMConfig
from .hexaplane import paired_halves, query_planes
from .nde import query_nde, reflect


def mlp(inputs: int, outputs: int, hidden: int, layers: int) -> nn.Sequential:
    mods: list[nn.Module] = []
    width = inputs
    for _ in range(layers):
        mods += [nn.Linear(width, hidden), nn.SiLU()]
        width = hidden
    mods.append(nn.Linear(width, outputs))
    return nn.Sequential(*mods)


class FieldHeads(nn.Module):
    def __init__(self, config: LIRMConfig):
        super().__init__()
        self.config = config
        f = 3 * config.plane_channels
        h, n = config.head_hidden, config.head_layers
        self.sdf = mlp(f, 1, h, n)
        self.albedo = mlp(f, 3, h, n)
        self.roughness = mlp(f, 1, h, n)
        self.metallic = mlp(f, 1, h, n)
        self.normal = mlp(f, 3, h, n)
        extra = config.nde_channels if config.colour == "nde" else 0
        self.colour = mlp(f + extra, 3, h, n)
        self.rho = mlp(f, 1, h, n) if config.colour == "nde" else None


@dataclass
class FieldSample:
    sdf: torch.Tensor  # (B, N)
    albedo: torch.Tensor  # (B, N, 3) linear, in (0, 1)
    roughness: torch.Tensor | None  # (B, N); None when sampled without materials
    metallic: torch.Tensor | None  # (B, N)
    normal: torch.Tensor  # (B, N, 3) unit, predicted by MLP_n
    colour: torch.Tensor | None  # (B, N, 3) view-dependent radiance (None when no view directions)


class Field:
    """A decoded reconstruction state: planes (and panoramas) plus the heads that read them."""

    def __init__(self, config: LIRMConfig, heads: FieldHeads, planes: torch.Tensor, panoramas: torch.Tensor | None,
                 fitted_beta: float | None = None):
        self.config = config
        self.heads = heads
        self.planes = planes
        self.panoramas = panoramas
        # The VolSDF beta a refinement fitted this field at (None: a decoded update). Its silhouettes sit
        # a few beta outside its zero level (export/silhouette_offset.py); the export corrects for that.
        self.fitted_beta = fitted_beta

    def item(self, b: int) -> "Field":
        """The field of batch entry `b` alone (the renderer takes one scene at a time)."""
        panoramas = None if self.panoramas is None else self.panoramas[b:b + 1]
        return Field(self.config, self.heads, self.planes[b:b + 1], panoramas, self.fitted_beta)

    @property
    def radius(self) -> float:
        return self.config.radius

    @property
    def normal_eps(self) -> float:
        """Central-difference step for numerical normals: 2 voxels of the hexa-plane (paper §3.4); the
        planes' own size, which a refined field (engine/refine/) may have raised above the decoder's."""
        return 2.0 * (2.0 * self.config.radius / self.planes.shape[-1])

    def features(self, points: torch.Tensor) -> torch.Tensor:
        planes = self.planes
        # The hexa-plane's halves side by side (a copy of the planes), made once for all the reads of a
        # step: while the planes are the same tensor, unchanged in place (its version counter, which
        # inference tensors do not keep: those are paired at every read, as a tri-plane has no halves).
        if planes.shape[1] != 6 or planes.is_inference():
            return query_planes(planes, points, self.config.radius)
        key = (id(planes), planes._version, torch.is_grad_enabled())
        cached = getattr(self, "_paired", None)  # (key, halves) in one attribute: a reader sees both or neither
        if cached is None or cached[0] != key:
            cached = self._paired = (key, paired_halves(planes))
        return query_planes(planes, points, self.config.radius, halves=cached[1])

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(B, N, 3) -> (B, N): MLP_s(f) + ||x|| - 0.1 R."""
        return self.heads.sdf(self.features(points))[..., 0] + self._sdf_bias(points)

    def _sdf_bias(self, points: torch.Tensor) -> torch.Tensor:
        return points.norm(dim=-1) - self.config.sdf_bias_fraction * self.config.radius

    def sample(self, points: torch.Tensor, view_dirs: torch.Tensor | None = None, materials: bool = True) -> FieldSample:
        """`materials=False` leaves roughness and metallic out (None): a fit of the radiance that does not
        read them saves two of the seven heads at every sample."""
        return self.sample_features(self.features(points), points, view_dirs, materials)

    def sdf_and_features(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N, 3) -> the SDF (B, N) and the plane features it was read from (B, N, F), so that the
        other heads can read the same features later at only some of the points (the refinement's
        samples that carry weight: ray_rendering.py)."""
        f = self.features(points)
        return self.heads.sdf(f)[..., 0] + self._sdf_bias(points), f

    def sample_features(self, f: torch.Tensor, points: torch.Tensor, view_dirs: torch.Tensor | None = None,
                        materials: bool = True, sdf: torch.Tensor | None = None) -> FieldSample:
        """`sample` from features already read at `points` (and the SDF there, when known)."""
        h = self.heads
        normal = F.normalize(h.normal(f), dim=-1)
        colour = None
        if view_dirs is not None:
            if self.config.colour == "nde":
                rho = torch.sigmoid(h.rho(f))[..., 0]
                f_d = query_nde(self.panoramas, reflect(view_dirs, normal), rho)
                colour = torch.sigmoid(h.colour(torch.cat([f, f_d], dim=-1)))
            else:
                colour = torch.sigmoid(h.colour(f))
        return FieldSample(
            sdf=h.sdf(f)[..., 0] + self._sdf_bias(points) if sdf is None else sdf,
            albedo=torch.sigmoid(h.albedo(f)),
            roughness=torch.sigmoid(h.roughness(f))[..., 0] if materials else None,
            metallic=torch.sigmoid(h.metallic(f))[..., 0] if materials else None,
            normal=normal,
            colour=colour,
        )


def device_of(field) -> torch.device:
    """Where a field's tensors live: the decoded LIRM field's planes, else the CPU (analytic fields)."""
    planes = getattr(field, "planes", None)
    return planes.device if isinstance(planes, torch.Tensor) else torch.device("cpu")


def volsdf_density(sdf: torch.Tensor, beta: float | torch.Tensor) -> torch.Tensor:
    """sigma = 1/2 exp(-s/beta) for s >= 0, 1 - 1/2 exp(s/beta) for s < 0 (paper eq. 9, as written;
    VolSDF scales it by 1/beta, which the renderer applies)."""
    half = 0.5 * torch.exp(-sdf.abs() / beta)
    return torch.where(sdf >= 0, half, 1.0 - half)
