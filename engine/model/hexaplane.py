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
    align_corners=False: the plane's outer edge is at +-R)."""
    b, p, c, h, w = planes.shape
    hexa = p == 6
    u = points / radius
    features = []
    for k, (a0, a1, side) in enumerate(PLANE_AXES):
        grid = torch.stack([u[..., a0], u[..., a1]], dim=-1).unsqueeze(1)  # (B, 1, N, 2)
        if hexa:
            pos = _sample(planes[:, 2 * k], grid)
            neg = _sample(planes[:, 2 * k + 1], grid)
            f = torch.where((points[..., side] >= 0).unsqueeze(-1), pos, neg)
        else:
            f = _sample(planes[:, k], grid)
        features.append(f)
    return torch.cat(features, dim=-1)


def _sample(plane: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
    """(B, C, H, W), (B, 1, N, 2) -> (B, N, C)."""
    return F.grid_sample(plane, grid, mode="bilinear", padding_mode="border", align_corners=False)[:, :, 0].transpose(1, 2)
