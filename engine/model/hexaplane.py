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


def query_planes(planes: torch.Tensor, points: torch.Tensor, radius: float) -> torch.Tensor:
    """planes (B, P, C, H, W) with P = 6 (hexa) or 3 (tri); points (B, N, 3) -> features (B, N, 3C).

    Plane rows follow the second axis and columns the first, both from -R to R (grid_sample's
    align_corners=False: the plane's outer edge is at +-R).

    All planes are sampled in one grid_sample call, each plane its own batch entry: indexing the
    planes one by one would make every backward pass zero-fill a gradient of the whole plane tensor
    per plane (a quarter of a refinement step's time on a CPU)."""
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
        # Each point reads the + half of a plane pair where its third coordinate is >= 0, else the -
        # half: a one-hot weighting rather than indexing, whose backward would zero-fill the whole
        # sampled tensor once per plane.
        sides = torch.stack([points[..., side] >= 0 for _, _, side in PLANE_AXES], dim=1)  # (B, 3, N)
        pick = torch.stack([sides, ~sides], dim=2).unsqueeze(-1).to(sampled.dtype)  # (B, 3, 2, N, 1)
        sampled = (sampled.reshape(b, 3, 2, -1, c) * pick).sum(dim=2)  # (B, 3, N, C)
    return sampled.permute(0, 2, 1, 3).reshape(b, -1, 3 * c)  # [xy | xz | yz] features per point
