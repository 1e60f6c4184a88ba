"""AdamW's second moments beside a slim checkpoint, in 8 bits: what lets a GPU slice continue without
the learning-rate warm-up a fresh optimizer needs.

A slim checkpoint (training_checkpoint.save_slim_checkpoint) drops the moments, since both in float16
would pass the 50 MB the repository keeps and the 64 MiB a device call carries; the next slice then
ramped its learning rate up over 50 steps, about a quarter of each call's steps at a reduced rate. The
second moment (the running mean of the squared gradient) is what makes early steps unsafe: without it
Adam's first updates are full-size sign steps. Stored as log2 in 8 bits per parameter (14.5 MB for
`small`; the step between codes about a quarter of an octave, so sqrt(v) within ±4.4%), it comes back
beside the weights; the first moments restart at zero, and since AdamW's step count is kept their bias
correction is about 1, so the updates grow over ~20 steps by themselves (1 - 0.9^k) at the scheduled rate.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file

from lirm.engine.io.atomic_files import atomic_write

log = logging.getLogger(__name__)

FORMAT = "lirm-adamw-second-moments-log2-u8"
SUFFIX = ".adam-v.safetensors"
_LEVELS = 254  # codes 1..255 span the tensor's positive log2 range; 0 is an exact zero


def second_moments_path(slim_path: str | Path) -> Path:
    """The companion of a slim checkpoint: `X.safetensors` -> `X.adam-v.safetensors`."""
    slim_path = Path(slim_path)
    return slim_path.with_name(slim_path.name.removesuffix(".safetensors") + SUFFIX)


def quantize_log2(v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Non-negative values -> (uint8 codes, float32 [lo, hi] of their positive log2 values)."""
    v = v.detach().float().cpu().reshape(-1)
    positive = v > 0
    if not positive.any():
        return torch.zeros(v.shape, dtype=torch.uint8), torch.zeros(2)
    logs = torch.log2(v[positive])
    lo, hi = logs.min(), logs.max()
    span = (hi - lo).clamp(min=1e-12)
    codes = torch.zeros(v.shape, dtype=torch.uint8)
    codes[positive] = (1 + torch.round((logs - lo) / span * _LEVELS)).to(torch.uint8)
    return codes, torch.stack([lo, hi])


def dequantize_log2(codes: torch.Tensor, bounds: torch.Tensor) -> torch.Tensor:
    lo, hi = float(bounds[0]), float(bounds[1])
    values = torch.exp2(lo + (codes.float() - 1) / _LEVELS * (hi - lo))
    return torch.where(codes > 0, values, torch.zeros_like(values))


def save_second_moments(slim_path: str | Path, model: torch.nn.Module, optimizer: torch.optim.Optimizer,
                        stage: int, step: int) -> Path | None:
    """Write the companion of `slim_path` for the run at (stage, step); None when the optimizer has no
    moments yet (nothing to keep)."""
    tensors, counts = {}, []
    for name, p in model.named_parameters():
        state = optimizer.state.get(p, {})
        if "exp_avg_sq" not in state:
            return None
        codes, bounds = quantize_log2(state["exp_avg_sq"])
        tensors[f"{name}/codes"], tensors[f"{name}/bounds"] = codes, bounds
        counts.append(float(state["step"]))
    metadata = {"format": FORMAT, "stage": str(stage), "step": str(step),
                "optimizer_steps": json.dumps(max(counts) if counts else 0.0)}
    path = second_moments_path(slim_path)
    return atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=metadata))


def load_second_moments(slim_path: str | Path, model: torch.nn.Module, stage: int, step: int) -> dict[str, torch.Tensor] | None:
    """The optimizer state to restore ("param/exp_avg_sq", zero "param/exp_avg", "param/step") from the
    companion of `slim_path`, or None (logged) when there is none or it is not this run's (stage, step),
    damaged, or for another model: the run then restarts its moments with the warm-up, as before."""
    path = second_moments_path(slim_path)
    if not path.is_file():
        return None
    try:
        with safe_open(str(path), framework="pt", device="cpu") as f:
            meta = f.metadata() or {}
            if meta.get("format") != FORMAT:
                log.warning("%s is not a file of AdamW's second moments; ignoring it", path)
                return None
            if (meta.get("stage"), meta.get("step")) != (str(stage), str(step)):
                log.warning("%s holds the second moments of stage %s step %s, not of the resumed stage %d step %d "
                            "(copied from another slice?); ignoring it: fresh moments with a warm-up",
                            path, meta.get("stage"), meta.get("step"), stage, step)
                return None
            optimizer_steps = torch.tensor(float(json.loads(meta.get("optimizer_steps", "0"))))
            state = {}
            for name, p in model.named_parameters():
                codes = f.get_tensor(f"{name}/codes")
                if codes.numel() != p.numel():
                    raise ValueError(f"{name} holds {codes.numel()} values, the model's parameter {p.numel()}")
                state[f"{name}/exp_avg_sq"] = dequantize_log2(codes, f.get_tensor(f"{name}/bounds")).view_as(p).to(p.dtype)
                state[f"{name}/exp_avg"] = torch.zeros_like(p, device="cpu")
                state[f"{name}/step"] = optimizer_steps.clone()
            return state
    except (SafetensorError, OSError, RuntimeError, ValueError, KeyError) as err:
        log.warning("cannot read AdamW's second moments from %s (%s); ignoring it: fresh moments with a warm-up", path, err)
        return None
