"""An image-space material prior: a small U-Net that reads one masked photo and predicts each object
pixel's metallic, roughness and albedo.

Why it exists (README, "The image-space material prior"): the per-scene fit cannot tell a gold line
from a dark paint or a paint's colour from its light's where the photos say nothing; what settles
it is knowledge of what materials look like, which the paper's transformer learns from many
objects. Until that prior is trained (issue 22 waits for GPU time), this network, small enough to
train on a laptop's CPU in half an hour from the same training scenes, carries that knowledge to
the refinement as a per-pixel target (refine/image_materials.py). It is a deviation from the paper:
LIRM predicts the materials in its hexa-plane, not per photo.

Input: the photo as the capture hands it (display sRGB, the object on white) and its mask.
Output per pixel: metallic in [0, 1] (a logit in training), roughness in [0, 1], linear albedo.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from lirm.engine.errors import LirmUserError

FORMAT = "lirm-material-net/1"
# The size the network was trained to see an object at: photos are brought to it (longer side) first.
WORKING_SIZE = 128


@dataclass(frozen=True)
class MaterialNetConfig:
    channels: tuple[int, ...] = (24, 48, 96, 128)  # per level, full resolution first
    groups: int = 8  # GroupNorm groups: one photo at a time at inference, so no batch statistics

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "MaterialNetConfig":
        return cls(channels=tuple(d["channels"]), groups=int(d["groups"]))


PRESETS = {"default": MaterialNetConfig(), "small": MaterialNetConfig(channels=(16, 32, 64, 96))}


def _block(cin: int, cout: int, groups: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, padding=1), nn.GroupNorm(min(groups, cout), cout), nn.SiLU(),
                         nn.Conv2d(cout, cout, 3, padding=1), nn.GroupNorm(min(groups, cout), cout), nn.SiLU())


class MaterialNet(nn.Module):
    INPUTS = 4  # sRGB on white, mask
    OUTPUTS = 5  # metallic logit, roughness logit, albedo logits (3)

    def __init__(self, config: MaterialNetConfig = MaterialNetConfig()):
        super().__init__()
        self.config = config
        c = config.channels
        self.down = nn.ModuleList([_block(self.INPUTS if i == 0 else c[i - 1], c[i], config.groups) for i in range(len(c))])
        self.up = nn.ModuleList([_block(c[i + 1] + c[i], c[i], config.groups) for i in range(len(c) - 1)])
        self.head = nn.Conv2d(c[0], self.OUTPUTS, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, 4, H, W) -> (B, 5, H, W) logits; H and W multiples of 2^(levels - 1)."""
        skips = []
        for i, block in enumerate(self.down):
            x = block(x if i == 0 else F.avg_pool2d(x, 2))
            skips.append(x)
        for i in reversed(range(len(self.up))):
            x = F.interpolate(x, scale_factor=2.0, mode="bilinear", align_corners=False)
            x = self.up[i](torch.cat([x, skips[i]], dim=1))
        return self.head(x)


def network_input(images: np.ndarray, masks: np.ndarray) -> torch.Tensor:
    """(V, H, W, 3) display sRGB on white and (V, H, W) masks -> the network's (V, 4, H, W)."""
    x = np.concatenate([np.asarray(images, np.float32), np.asarray(masks, np.float32)[..., None]], axis=-1)
    return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 3, 1, 2)))


def object_exposure(images: np.ndarray, masks: np.ndarray, gain) -> np.ndarray:
    """(V, H, W, 3) photos on white with the object's display values scaled by `gain` (a number, or
    one per photo broadcast as (V, 1, 1, 1)): the white around the object stays white, as the
    capture's crop makes it. The training's exposure jitter and the familiarity check's variants."""
    return np.clip(1.0 - masks[..., None] + masks[..., None] * images * gain, 0.0, 1.0)


@dataclass
class PixelMaterials:
    """Per-pixel predictions for V photos, at the photos' own size."""

    metallic: np.ndarray  # (V, H, W)
    roughness: np.ndarray  # (V, H, W)
    albedo: np.ndarray  # (V, H, W, 3) linear


def decode_outputs(logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    probabilities = torch.sigmoid(logits)
    return probabilities[:, 0], probabilities[:, 1], probabilities[:, 2:5]


@torch.no_grad()
def predict_materials(net: MaterialNet, images: np.ndarray, masks: np.ndarray, batch: int = 8) -> PixelMaterials:
    """The network's materials for each photo. Photos are resized so that their longer side is the
    working size (padded to the network's multiple), predicted, and resized back."""
    net.eval()
    views, height, width = np.asarray(masks).shape
    scale = WORKING_SIZE / max(height, width)
    h, w = max(1, round(height * scale)), max(1, round(width * scale))
    multiple = 2 ** (len(net.config.channels) - 1)
    ph, pw = -(-h // multiple) * multiple, -(-w // multiple) * multiple
    outputs = []
    for start in range(0, views, batch):
        x = network_input(images[start:start + batch], masks[start:start + batch])
        if (h, w) != (height, width):
            x = F.interpolate(x, size=(h, w), mode="area" if scale < 1 else "bilinear")
        x = F.pad(x, (0, pw - w, 0, ph - h), value=1.0)
        x[:, 3, h:, :] = 0.0
        x[:, 3, :, w:] = 0.0
        metallic, roughness, albedo = decode_outputs(net(x))
        y = torch.cat([metallic[:, None], roughness[:, None], albedo], 1)[:, :, :h, :w]
        if (h, w) != (height, width):
            y = F.interpolate(y, size=(height, width), mode="bilinear", align_corners=False)
        outputs.append(y)
    y = torch.cat(outputs).numpy()
    return PixelMaterials(y[:, 0], y[:, 1], y[:, 2:5].transpose(0, 2, 3, 1).copy())


def save_material_net(net: MaterialNet, path: str | Path, metadata: dict | None = None) -> Path:
    from safetensors.torch import save_file

    from lirm.engine.io.atomic_files import atomic_write

    from .checkpoint import require_safetensors_name

    path = require_safetensors_name(path)
    tensors = {k: v.detach().cpu().contiguous().clone() for k, v in net.state_dict().items()}
    header = {"format": FORMAT, "config": json.dumps(net.config.to_dict()), "extra": json.dumps(metadata or {})}
    atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=header))
    return path


def load_material_net(path: str | Path) -> tuple[MaterialNet, dict]:
    """The network and its metadata; a file that is not one names itself and what to do."""
    from safetensors import SafetensorError, safe_open

    path = Path(path)
    if not path.is_file():
        raise LirmUserError(f"material network {path} not found; train one with `lirm train-materials` or leave the "
                            "image-space material prior off")
    try:
        with safe_open(str(path), framework="pt") as f:
            header = f.metadata() or {}
            if header.get("format") != FORMAT:
                raise LirmUserError(f"{path} is not a material network (format {header.get('format')!r}, expected "
                                    f"{FORMAT!r}); pass the file `lirm train-materials` wrote")
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except SafetensorError as err:
        raise LirmUserError(f"material network {path} is unreadable ({err}); download or train it again") from err
    net = MaterialNet(MaterialNetConfig.from_dict(json.loads(header["config"])))
    try:
        net.load_state_dict(tensors)
    except RuntimeError as err:
        raise LirmUserError(f"material network {path} does not match its own config ({err}); train it again") from err
    bad = [k for k, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]
    if bad:
        raise LirmUserError(f"material network {path} holds NaN or infinite weights ({bad[0]}); train it again")
    return net, json.loads(header.get("extra", "{}"))
