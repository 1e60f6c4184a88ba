"""Which weights a reconstruction uses: a checkpoint the user names, else the one shipped under
resources/checkpoints/, else freshly initialised weights, which are untrained and say so.

No trained checkpoint ships yet (issue 7 trains it), so without --checkpoint the model is untrained:
its output is the s_bias prior's small sphere with noise, not the object. Callers must show
`ModelSource.warning` where the user sees it.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import torch

from .checkpoint import load_checkpoint
from .config import preset
from .lirm import LIRM

SHIPPED = {"small": "lirm-small.safetensors", "tiny": "lirm-tiny.safetensors"}


@dataclass
class ModelSource:
    model: LIRM
    trained: bool
    description: str  # where the weights came from, for logs and summaries
    extra: dict

    @property
    def warning(self) -> str | None:
        if self.trained:
            return None
        return ("WARNING: the LIRM weights are UNTRAINED (no trained checkpoint was given or shipped); "
                "the reconstruction will not look like the object. Pass --checkpoint PATH to a trained model.")


def shipped_checkpoint(preset_name: str) -> Path | None:
    name = SHIPPED.get(preset_name)
    if name is None:
        return None
    path = Path(str(resources.files("lirm.resources"))) / "checkpoints" / name
    return path if path.exists() else None


def load_model(checkpoint: str | Path | None = None, preset_name: str = "small", device: str | torch.device = "cpu",
               seed: int = 0) -> ModelSource:
    if checkpoint is not None:
        model, extra = load_checkpoint(checkpoint, device=device)
        return ModelSource(model, bool(extra.get("trained", False)), f"checkpoint {checkpoint}", extra)
    shipped = shipped_checkpoint(preset_name)
    if shipped is not None:
        model, extra = load_checkpoint(shipped, expected=preset_name, device=device)
        return ModelSource(model, bool(extra.get("trained", False)), f"shipped checkpoint {shipped.name}", extra)
    with torch.random.fork_rng(devices=[]):  # the same untrained weights every run, the caller's RNG untouched
        torch.manual_seed(seed)
        model = LIRM(preset(preset_name)).to(device).eval()
    return ModelSource(model, False, f"untrained '{preset_name}' weights (seed {seed})", {"trained": False})
