"""Training checkpoints: the model's weights plus everything needed to continue the same run
exactly — the AdamW moments, the stage, the step and the run's settings (the data of every step is
derived from the data seed and the step, training_sample.py, so no RNG state needs saving).

They are ordinary LIRM checkpoints (engine/model/checkpoint.py) with the optimizer state under the
`training.` prefix, so `lirm reconstruct --checkpoint` and `lirm eval` read them directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.model.checkpoint import load_checkpoint, load_training_tensors, peek_checkpoint, save_checkpoint
from lirm.engine.model.lirm import LIRM

from .second_moments import load_second_moments, save_second_moments

_MOMENTS = ("exp_avg", "exp_avg_sq", "step")


@dataclass
class ResumePoint:
    model: LIRM
    stage: int
    step: int  # iterations done in that stage
    run: dict  # the run's settings as saved
    optimizer_state: dict[str, torch.Tensor]  # "param_name/moment" -> tensor (empty for model-only checkpoints)
    moments_dropped: bool = False  # a slim checkpoint: continue at `step` with fresh AdamW moments
    second_moments: bool = False  # ... but its second moments were beside it (second_moments.py): no warm-up


def save_training_checkpoint(path: Path, model: LIRM, optimizer: torch.optim.Optimizer, stage: int, step: int,
                             run: dict) -> Path:
    names = {id(p): n for n, p in model.named_parameters()}
    tensors = {}
    for group in optimizer.param_groups:
        for p in group["params"]:
            for key, value in optimizer.state.get(p, {}).items():
                if key in _MOMENTS and torch.is_tensor(value):
                    tensors[f"{names[id(p)]}/{key}"] = value
    metadata = {"training": {"stage": stage, "step": step, "run": run}, "trained": True}
    return save_checkpoint(model, path, metadata=metadata, training_tensors=tensors)


def save_slim_checkpoint(path: Path, model: LIRM, stage: int, step: int, run: dict,
                         optimizer: torch.optim.Optimizer | None = None) -> Path:
    """The weights in float16 with the stage and step but no AdamW moments: a third of a full
    checkpoint's size, small enough to keep in the repository and carry between GPU slices. A run
    resumed from it continues the same step (and so the same data and schedule). With `optimizer`, its
    second moments are written beside it in 8 bits (second_moments.py), and a resumed run restores them
    and needs no warm-up; without them its moments restart and the learning rate warms up again over a
    few steps (trainer.MOMENT_RESTART_STEPS)."""
    metadata = {"training": {"stage": stage, "step": step, "run": run, "moments": "dropped"}, "trained": True}
    written = save_checkpoint(model, path, dtype=torch.float16, metadata=metadata)
    if optimizer is not None:
        save_second_moments(path, model, optimizer, stage, step)
    return written


def load_resume_point(path: str | Path, preset: str) -> ResumePoint:
    """Everything in a checkpoint to continue from; errors name the file and what to pass instead."""
    config, extra = peek_checkpoint(path)
    model, _ = load_checkpoint(path, expected=preset)
    training = extra.get("training")
    if not isinstance(training, dict) or not {"stage", "step"} <= set(training):
        # A model-only checkpoint (e.g. the shipped one) can still start a stage from its weights.
        return ResumePoint(model, 0, 0, {}, {})
    stage, step, dropped = int(training["stage"]), int(training["step"]), training.get("moments") == "dropped"
    state = load_training_tensors(path)
    second = load_second_moments(path, model, stage, step) if dropped else None
    return ResumePoint(model, stage, step, dict(training.get("run") or {}), second or state,
                       moments_dropped=dropped, second_moments=second is not None)


def restore_optimizer(optimizer: torch.optim.Optimizer, model: LIRM, state: dict[str, torch.Tensor], path: str | Path) -> None:
    params = dict(model.named_parameters())
    missing = [n for n in params if f"{n}/exp_avg" not in state]
    if missing:
        raise LirmUserError(f"checkpoint {path} has no optimizer state for {len(missing)} parameters (e.g. {missing[0]}); "
                            f"it is damaged or was not saved by lirm train; resume from another checkpoint of the run")
    for n, p in params.items():
        # AdamW keeps its step count on the CPU (unless capturable); the moments live with the parameter.
        optimizer.state[p] = {k: state[f"{n}/{k}"] if k == "step" else state[f"{n}/{k}"].to(p.device)
                              for k in _MOMENTS if f"{n}/{k}" in state}
