"""One optimisation step of training, shared by the trainer and `lirm bench train` so that what the
benchmark times is exactly what a run does: the sample to the device, the update sets with their
losses under bf16 autocast (GPUs), backward, gradient clipping, AdamW. A step whose loss or gradient
norm is not finite changes nothing (the caller counts it)."""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass

import torch

from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.model.volume_renderer import VolumeRenderConfig

from .stages import StageConfig
from .training_sample import TrainingSample


def training_optimizer(model: torch.nn.Module, learning_rate: float) -> torch.optim.AdamW:
    # Weight decay as MeshLRM's; the paper gives only the betas.
    return torch.optim.AdamW(model.parameters(), lr=learning_rate, betas=(0.9, 0.95), weight_decay=0.05)


def training_render(stage: StageConfig, inv_beta: float) -> VolumeRenderConfig:
    """How a step renders its crops: the stage's samples per ray, stratified, at the step's 1/beta."""
    return VolumeRenderConfig(samples_per_ray=stage.samples_per_ray, beta=1.0 / inv_beta, stratified=True,
                              numerical_normals=stage.numerical_normal_weight > 0)


@dataclass
class StepOutcome:
    loss: torch.Tensor
    terms: dict[str, float]
    grad_norm: torch.Tensor
    applied: bool  # False: a non-finite loss or gradient, the weights left as they were


def train_step(step_module: torch.nn.Module, model: torch.nn.Module, optimizer: torch.optim.Optimizer,
               sample: TrainingSample, render: VolumeRenderConfig, occupancy: OccupancyConfig | None,
               generator: torch.Generator, device: torch.device) -> StepOutcome:
    inputs = [tuple(t.to(device, non_blocking=True) for t in views) for views in sample.inputs]
    targets = [[{k: v.to(device, non_blocking=True) for k, v in scene.items()} for scene in per_update]
               for per_update in sample.targets]
    autocast = torch.autocast("cuda", dtype=torch.bfloat16) if device.type == "cuda" else nullcontext()
    with autocast:
        loss, terms = step_module(inputs, targets, sample.crop, render, occupancy, generator)
    optimizer.zero_grad(set_to_none=True)
    with torch.profiler.record_function("backward"):
        loss.backward()
    with torch.profiler.record_function("optimizer"):
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        # Gradients are already averaged over processes (DDP), so every rank takes the same decision.
        applied = bool(torch.isfinite(loss)) and bool(torch.isfinite(grad_norm))
        if applied:
            optimizer.step()
    return StepOutcome(loss, terms, grad_norm, applied)
