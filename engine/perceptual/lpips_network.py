"""The LPIPS distance (v0.1, "lin"): images through an ImageNet trunk, each tapped layer's features
unit-normalised over channels, their squared difference weighted per channel by the learned heads,
averaged over the image and summed over the layers. AlexNet for the metric (LPIPS' own default for
evaluation), VGG16 for the training loss (its authors' advice for optimisation).

Written from the LPIPS paper and the trunks' published shapes; the weights are read from the
safetensors that `lpips_weights.py` writes. Images smaller than a trunk can take (AlexNet's stride-4
convolution and two 3 x 3 pools need 32 px, VGG's four pools 16) are enlarged bilinearly first.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from ..errors import LirmUserError
from .lpips_weights import missing_weights_reason, weights_path

# Per convolution: (in, out, kernel, stride, padding); then where the trunk pools and which ReLUs LPIPS reads.
ALEX_CONVS = [(3, 64, 11, 4, 2), (64, 192, 5, 1, 2), (192, 384, 3, 1, 1), (384, 256, 3, 1, 1), (256, 256, 3, 1, 1)]
VGG_WIDTHS = [64, 64, 128, 128, 256, 256, 256, 512, 512, 512, 512, 512, 512]
TRUNK_SPECS = {
    "alex": {"convs": ALEX_CONVS, "pool_before": {1: (3, 2), 2: (3, 2)}, "taps": {0, 1, 2, 3, 4}, "min_side": 32},
    "vgg": {"convs": [(VGG_WIDTHS[i - 1] if i else 3, w, 3, 1, 1) for i, w in enumerate(VGG_WIDTHS)],
            "pool_before": {2: (2, 2), 4: (2, 2), 7: (2, 2), 10: (2, 2)}, "taps": {1, 3, 6, 9, 12}, "min_side": 16},
}
# LPIPS' input scaling, applied to images in [-1, 1].
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)


class LPIPS(nn.Module):
    """`LPIPS(network)(x, y)`: the distance per image of (N, 3, H, W) batches in [0, 1] (display-referred
    RGB, as a person sees them), shape (N,). Differentiable in both; its own weights are frozen."""

    def __init__(self, network: str = "alex"):
        super().__init__()
        spec = TRUNK_SPECS[network]
        self.network = network
        self.spec = spec
        self.trunk = nn.ModuleList(nn.Conv2d(i, o, k, stride=s, padding=p) for i, o, k, s, p in spec["convs"])
        widths = [spec["convs"][i][1] for i in sorted(spec["taps"])]
        self.heads = nn.ParameterList(nn.Parameter(torch.zeros(w)) for w in widths)
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1))
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1))
        self.requires_grad_(False)
        self.eval()

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        taps = []
        for i, conv in enumerate(self.trunk):
            if i in self.spec["pool_before"]:
                kernel, stride = self.spec["pool_before"][i]
                x = F.max_pool2d(x, kernel, stride)
            x = F.relu(conv(x))
            if i in self.spec["taps"]:
                taps.append(x)
        return taps

    def forward(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        if x.shape != y.shape or x.ndim != 4 or x.shape[1] != 3:
            raise ValueError(f"LPIPS compares two (N, 3, H, W) batches of one shape, got {tuple(x.shape)} and {tuple(y.shape)}")
        side = min(x.shape[-2:])
        if side < self.spec["min_side"]:
            size = [int(round(s * self.spec["min_side"] / side)) for s in x.shape[-2:]]
            x, y = (F.interpolate(a, size=size, mode="bilinear", align_corners=False) for a in (x, y))
        both = torch.cat([x, y]) * 2.0 - 1.0
        taps = self.features((both - self.shift) / self.scale)
        distance = x.new_zeros(x.shape[0])
        for head, feature in zip(self.heads, taps):
            unit = feature / (feature.pow(2).sum(1, keepdim=True).sqrt() + 1e-10)
            fx, fy = unit.chunk(2)
            distance = distance + ((fx - fy) ** 2 * head.view(1, -1, 1, 1)).sum(1).mean((-2, -1))
        return distance

    @torch.no_grad()
    def image_distance(self, a, b) -> float:
        """The distance of two (H, W, 3) images in [0, 1] (numpy or anything array-like), on this network's
        device: what the metric scores one picture pair with."""
        device = self.shift.device
        as_batch = lambda image: torch.as_tensor(np.ascontiguousarray(image, np.float32)).permute(2, 0, 1)[None].to(device)  # noqa: E731
        return float(self(as_batch(a), as_batch(b))[0])


def load_lpips(network: str = "alex", path: Path | None = None) -> LPIPS:
    """The network with its weights; a LirmUserError saying how to fetch them when they are not here."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    if path is not None and not path.is_file():
        raise LirmUserError(f"{path}: no such file (LPIPS {network} weights are written by `lirm fetch lpips --to FOLDER`)")
    path = path or weights_path(network)
    if not path.is_file():
        raise LirmUserError(missing_weights_reason(network))
    try:
        state = load_file(str(path))
    except (SafetensorError, OSError) as err:
        raise LirmUserError(f"{path}: not readable LPIPS weights ({err}); run `lirm fetch lpips` again") from err
    net = LPIPS(network)
    expected = {k: v.shape for k, v in net.state_dict().items() if k not in ("shift", "scale")}
    found = {k: v.shape for k, v in state.items()}
    if found != expected:
        raise LirmUserError(f"{path}: these are not LPIPS {network} weights (other tensors or shapes); run `lirm fetch lpips` again")
    net.load_state_dict(state, strict=False)
    return net
