"""The perceptual loss on RGB and albedo crops (paper §3.4: "LPIPS ... essential to recover texture
details"), with a documented substitute where LPIPS cannot run.

LPIPS needs ImageNet VGG weights, which this project cannot download (no internet beyond package
registries). `perceptual_loss()` uses LPIPS when the `lpips` package is installed and the VGG16
weights are already in torch's hub cache; otherwise it says so and uses a multi-scale SSIM plus an
image-gradient L1 loss, differentiable and weight-free: SSIM rewards local structure and contrast,
the gradient term edges, which is what LPIPS brings over L2 for texture detail.
"""

from __future__ import annotations

import logging
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

log = logging.getLogger(__name__)

VGG16_WEIGHTS = "vgg16-397923af.pth"  # the file torchvision's pretrained VGG16 loads from the hub cache


def lpips_available() -> tuple[bool, str]:
    """(available, why not): the lpips package and locally cached VGG16 weights."""
    try:
        import lpips  # noqa: F401
    except ImportError:
        return False, "the lpips package is not installed"
    cached = Path(torch.hub.get_dir()) / "checkpoints" / VGG16_WEIGHTS
    if not cached.is_file():
        return False, f"the VGG16 ImageNet weights are not in {cached.parent} (they cannot be downloaded here)"
    return True, ""


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
    name = "lpips-vgg"

    def __init__(self):
        super().__init__()
        import lpips

        self.net = lpips.LPIPS(net="vgg", verbose=False).eval()
        for p in self.net.parameters():
            p.requires_grad_(False)

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.net(x * 2 - 1, y * 2 - 1).mean()  # LPIPS takes [-1, 1]


def perceptual_loss(prefer_lpips: bool = True) -> nn.Module:
    """LPIPS when it can run here, else the SSIM + gradient substitute (logged once)."""
    if prefer_lpips:
        ok, why = lpips_available()
        if ok:
            return LPIPSLoss()
        log.warning("LPIPS is skipped: %s; using multi-scale SSIM + gradient loss instead", why)
    return SSIMGradientLoss()
