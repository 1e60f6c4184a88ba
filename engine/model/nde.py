"""Neural directional encoding (paper eqs. 10-16): N feature panoramas predicted by the transformer,
queried at the reflection direction and a learned panorama index rho."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from .config import LIRMConfig


class NDEDecoder(nn.Module):
    """NDE tokens (t x t) -> N panoramas of (t * p) x (t * p) pixels and C channels (paper eq. 12)."""

    def __init__(self, config: LIRMConfig):
        super().__init__()
        self.config = config
        self.linear = nn.Linear(config.width, config.nde_panoramas * config.nde_patch**2 * config.nde_channels)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        """(B, t*t, width) -> (B, C, N, H, W): rows follow theta in [0, pi], columns phi in [-pi, pi]."""
        c = self.config
        b = tokens.shape[0]
        t, p, n, ch = c.nde_tokens, c.nde_patch, c.nde_panoramas, c.nde_channels
        x = self.linear(tokens).view(b, t, t, n, p, p, ch)
        return x.permute(0, 6, 3, 1, 4, 2, 5).reshape(b, ch, n, t * p, t * p)


def reflect(view_dirs: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """l = v - 2 (v . n) n, with v the ray direction (toward the surface)."""
    return view_dirs - 2.0 * (view_dirs * normals).sum(-1, keepdim=True) * normals


def query_nde(panoramas: torch.Tensor, directions: torch.Tensor, rho: torch.Tensor) -> torch.Tensor:
    """Trilinear lookup of panoramas (B, C, N, H, W) at unit directions (B, M, 3) and rho (B, M) in
    [0, 1] (0 = first panorama, 1 = last); returns (B, M, C).

    phi = atan2(l0, l1) and theta = arccos(l2) as the paper writes them (eq. 14)."""
    # Kept off the poles: acos has an infinite derivative at +-1 and atan2 an undefined one at (0, 0),
    # either of which turns a training step's gradients into NaN.
    eps = 1e-6
    phi = torch.atan2(directions[..., 0], directions[..., 1] + eps * (directions[..., 1] == 0))
    theta = torch.acos(directions[..., 2].clamp(-1.0 + eps, 1.0 - eps))
    grid = torch.stack([phi / math.pi, theta / math.pi * 2.0 - 1.0, rho * 2.0 - 1.0], dim=-1)  # x=W, y=H, z=N
    out = F.grid_sample(panoramas, grid[:, :, None, None, :], mode="bilinear", padding_mode="border", align_corners=True)
    return out[:, :, :, 0, 0].transpose(1, 2)
