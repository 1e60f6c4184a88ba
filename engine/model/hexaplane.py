"""Hexa-plane (and tri-plane) features (paper eq. 8).

Plane order: xy, xz, yz; for the hexa-plane each has a + and a - half: xy+ xy- xz+ xz- yz+ yz-.
f_xy(x) samples T_xy+ when z >= 0 and T_xy- otherwise; f_xz uses the sign of y and f_yz that of x.
The three features are concatenated. Planes span [-R, R] on both of their axes.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .config import LIRMConfig

# (first axis, second axis, the axis whose sign picks the half) for xy, xz, yz
PLANE_AXES = ((0, 1, 2), (0, 2, 1), (1, 2, 0))


class PlaneDecoder(nn.Module):
    """Each plane token -> a plane_patch x plane_patch patch of plane_channels features (paper eq. 4)."""

    def __init__(self, config: LIRMConfig):
        super().__init__()
        self.config = config
        self.linear = nn.Linear(config.width, config.plane_patch**2 * config.plane_channels)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """(B, planes * t * t, width) -> (B, planes, C, t*p, t*p)."""
        c = self.config
        b = tokens.shape[0]
        t, p, ch = c.plane_tokens, c.plane_patch, c.plane_channels
        x = self.linear(tokens).view(b, c.num_planes, t, t, p, p, ch)
        return x.permute(0, 1, 6, 2, 4, 3, 5).reshape(b, c.num_planes, ch, t * p, t * p)


def paired_halves(planes: torch.Tensor) -> torch.Tensor:
    """Hexa-planes (B, 6, C, H, W) -> (B*3, C, H, 2W): each pair's + half beside its - half, so that one
    bilinear read per axis serves every point (query_planes). A copy: a caller that reads the same
    planes many times (Field.features) keeps it while the planes are unchanged."""
    b, p, c, h, w = planes.shape
    return planes.reshape(b, 3, 2, c, h, w).permute(0, 1, 3, 4, 2, 5).reshape(b * 3, c, h, 2 * w)


def query_planes(planes: torch.Tensor, points: torch.Tensor, radius: float, halves: torch.Tensor | None = None) -> torch.Tensor:
    """planes (B, P, C, H, W) with P = 6 (hexa) or 3 (tri); points (B, N, 3) -> features (B, N, 3C).
    `halves`: paired_halves(planes), when the caller has it already.

    Plane rows follow the second axis and columns the first, both from -R to R (grid_sample's
    align_corners=False: the plane's outer edge is at +-R).

    One grid_sample call reads every plane: indexing them one by one would make every backward pass
    zero-fill a gradient of the whole plane tensor per plane (a quarter of a refinement step's time on
    a CPU). For the hexa-plane each point reads only the half its third coordinate picks, in the
    pair's halves laid side by side: its column is clamped to the half's outer texel centres (what
    border padding does to a plane alone), so the bilinear read never reaches into the other half.
    Reading both halves and keeping one did twice the sampling (query_planes_reference, the tests'
    reference)."""
    b, p, c, h, w = planes.shape
    if p != 6:
        return query_planes_reference(planes, points, radius)
    if halves is None:
        halves = paired_halves(planes)
    u = points / radius
    edge = 1.0 - 1.0 / w  # the outermost texel centres, in grid_sample's normalised coordinates
    grids = []
    for a0, a1, side in PLANE_AXES:
        minus = (points[..., side] < 0).to(u.dtype)
        column = 0.5 * (u[..., a0].clamp(-edge, edge) + 1.0) + minus - 1.0  # the + half on [-1, 0], the - half on [0, 1]
        grids.append(torch.stack([column, u[..., a1]], dim=-1))
    grid = torch.stack(grids, dim=1).reshape(b * 3, 1, -1, 2)  # (B*3, 1, N, 2)
    sampled = F.grid_sample(halves, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return sampled[:, :, 0].reshape(b, 3, c, -1).permute(0, 3, 1, 2).reshape(b, -1, 3 * c)  # [xy | xz | yz]


def query_planes_reference(planes: torch.Tensor, points: torch.Tensor, radius: float) -> torch.Tensor:
    """query_planes by reading both halves of every pair and keeping the one the point's side picks:
    twice the sampling, kept as the plain statement of what the fast path computes (and for the
    tri-plane, which has no halves)."""
    b, p, c, h, w = planes.shape
    hexa = p == 6
    u = points / radius
    grids = [torch.stack([u[..., a0], u[..., a1]], dim=-1) for a0, a1, _ in PLANE_AXES]  # 3 x (B, N, 2)
    if hexa:
        grids = [g for g in grids for _ in range(2)]  # the + and - halves read the same coordinates
    grid = torch.stack(grids, dim=1).reshape(b * p, 1, -1, 2)  # (B*P, 1, N, 2)
    sampled = F.grid_sample(planes.reshape(b * p, c, h, w), grid, mode="bilinear", padding_mode="border", align_corners=False)
    sampled = sampled[:, :, 0].reshape(b, p, c, -1).transpose(2, 3)  # (B, P, N, C)
    if hexa:
        sides = torch.stack([points[..., side] >= 0 for _, _, side in PLANE_AXES], dim=1)  # (B, 3, N)
        pick = torch.stack([sides, ~sides], dim=2).unsqueeze(-1).to(sampled.dtype)  # (B, 3, 2, N, 1)
        sampled = (sampled.reshape(b, 3, 2, -1, c) * pick).sum(dim=2)  # (B, 3, N, C)
    return sampled.permute(0, 2, 1, 3).reshape(b, -1, 3 * c)  # [xy | xz | yz] features per point
