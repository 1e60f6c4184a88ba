"""Image tokens (paper eq. 6): non-overlapping p x p patches of [I, I_bg, (v, v x o)] -> one Linear."""

from __future__ import annotations

import torch
from torch import nn

from .config import LIRMConfig

INPUT_CHANNELS = 12  # masked RGB 3 + background RGB 3 + Plücker 6


class ImageTokenizer(nn.Module):
    def __init__(self, config: LIRMConfig):
        super().__init__()
        self.patch = config.patch
        self.proj = nn.Linear(INPUT_CHANNELS * config.patch**2, config.width)
        with torch.no_grad():
            # The background image's weights start at zero (as in the authors' LRM baseline): the
            # network learns to use the surroundings without their first disturbing the object.
            w = self.proj.weight.view(config.width, INPUT_CHANNELS, config.patch, config.patch)
            w[:, 3:6] = 0.0

    def forward(self, image: torch.Tensor, image_bg: torch.Tensor, plucker: torch.Tensor) -> torch.Tensor:
        """(B, V, 3, H, W), (B, V, 3, H, W), (B, V, 6, H, W) -> (B, V * H/p * W/p, width)."""
        x = torch.cat([image, image_bg, plucker], dim=2)
        b, v, c, h, w = x.shape
        p = self.patch
        x = x.reshape(b, v, c, h // p, p, w // p, p).permute(0, 1, 3, 5, 2, 4, 6)
        return self.proj(x.reshape(b, v * (h // p) * (w // p), c * p * p))
