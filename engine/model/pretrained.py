"""Which weights a reconstruction uses: a checkpoint the user names, else the one shipped under
resources/checkpoints/ (of the preset asked for, or when none is asked for, the largest shipped), else
freshly initialised weights, which are untrained and say so.

Untrained output is the s_bias prior's small sphere with noise, not the object: callers must show
`ModelSource.warning` where the user sees it. See resources/checkpoints/MODEL_CARD.md for what ships.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import torch

from .checkpoint import load_checkpoint
from .config import preset
from .lirm import LIRM

# In order of preference when no preset is asked for: the largest model that ships.
SHIPPED = {"small": "lirm-small.safetensors", "tiny": "lirm-tiny.safetensors"}
DEFAULT_PRESET = "small"  # what an untrained fallback builds when nothing ships


@dataclass
class ModelSource:
    model: LIRM
    trained: bool
    description: str  # where the weights came from, for logs and summaries
    extra: dict

    @property
    def note(self) -> str | None:
        """What the weights' maker says the user should know (shipped checkpoints carry one)."""
        note = self.extra.get("note")
        return str(note) if note else None

    @property
    def warning(self) -> str | None:
        if self.trained:
            return None
        return ("WARNING: the LIRM weights are UNTRAINED (no trained checkpoint was given or shipped); "
                "the reconstruction will not look like the object. Pass --checkpoint PATH to a trained model.")


def checkpoints_folder() -> Path:
    """The installed package's resources/checkpoints (not a path relative to wherever a command runs)."""
    return Path(str(resources.files("lirm.resources"))) / "checkpoints"


def shipped_file(name: str) -> Path | None:
    """resources/checkpoints/`name` of the installed package, when it is there."""
    path = checkpoints_folder() / name
    return path if path.exists() else None


def shipped_checkpoint(preset_name: str) -> Path | None:
    name = SHIPPED.get(preset_name)
    return None if name is None else shipped_file(name)


def default_preset() -> str:
    """The preset used when the user names none: the largest one that ships trained weights."""
    return next((name for name in SHIPPED if shipped_checkpoint(name) is not None), DEFAULT_PRESET)


def load_model(checkpoint: str | Path | None = None, preset_name: str | None = None, device: str | torch.device = "cpu",
               seed: int = 0) -> ModelSource:
    preset_name = preset_name or default_preset()
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
