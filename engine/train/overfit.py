"""The capacity experiment (the paper's single-object test): train the whole network, end to end
through one update and the volume renderer, on the views of a single object, and see how well its
hexa-plane field can reproduce them.

One object rendered by our renderer (spatially varying PBR) from 4 views; each step runs
update(initial state, the 4 views) -> decode -> render a random batch of the same views' rays, with
L2 on colour and on albedo (both over white, which also teaches the silhouette). 1/beta ramps up
as in the supplementary's stage 1. The result reports the input views' PSNR and the albedo PSNR
(Stanford-ORB per-channel scale) from full renders.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np
import torch

from lirm.engine.metrics import psnr, scaled_albedo_psnr
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera, render_rays
from lirm.engine.synth.object_views import ObjectViews, ObjectViewsConfig, protocol_cameras, render_object_views

from .ray_batches import RayTargets


@dataclass(frozen=True)
class OverfitConfig:
    preset: str = "tiny"
    views: ObjectViewsConfig = field(default_factory=ObjectViewsConfig)
    environment: str = "studio"
    azimuths_deg: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0)
    elevations_deg: tuple[float, ...] = (20.0, 40.0, 20.0, 40.0)
    steps: int = 1500
    rays_per_step: int = 1024
    object_ray_fraction: float = 0.5  # of each batch drawn from the object's pixels (the rest: any pixel)
    samples_per_ray: int = 48
    learning_rate: float = 2e-3
    final_learning_rate: float = 1e-4
    warmup_steps: int = 50
    inv_beta: tuple[float, float] = (20.0, 200.0)  # 1/beta from, to: linear over the first half
    albedo_weight: float = 1.0
    eval_every: int = 250
    eval_samples_per_ray: int = 128
    max_skipped_steps: int = 20  # non-finite steps tolerated (skipped) before giving up
    seed: int = 0


@dataclass
class OverfitResult:
    config: dict
    history: list[dict]  # step, loss, (at evaluations) psnr and albedo_psnr
    psnr_per_view: list[float]
    albedo_psnr_per_view: list[float]
    seconds: float  # training, evaluations excluded
    seconds_per_step: float
    renders: list[dict] = field(default_factory=list, repr=False)  # final renders per view: colour, albedo, opacity

    @property
    def psnr(self) -> float:
        return float(np.mean(self.psnr_per_view))

    @property
    def albedo_psnr(self) -> float:
        return float(np.mean(self.albedo_psnr_per_view))

    def to_dict(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "renders"}
        return {**d, "psnr": self.psnr, "albedo_psnr": self.albedo_psnr}


def render_training_views(config: OverfitConfig) -> ObjectViews:
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer
    from lirm.renderer.procedural_environments import make_procedural_environment

    cameras = protocol_cameras(list(config.azimuths_deg), list(config.elevations_deg), config.views.size, config.views.fov_deg)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        return render_object_views(renderer, make_procedural_environment(config.environment, width=512), cameras, config.views)
    finally:
        renderer.release()
        ctx.release()


def learning_rate(config: OverfitConfig, step: int) -> float:
    if step < config.warmup_steps:
        return config.learning_rate * (step + 1) / config.warmup_steps
    progress = (step - config.warmup_steps) / max(config.steps - config.warmup_steps, 1)
    return config.final_learning_rate + 0.5 * (config.learning_rate - config.final_learning_rate) * (1 + math.cos(math.pi * progress))


def inverse_beta(config: OverfitConfig, step: int) -> float:
    start, end = config.inv_beta
    return start + (end - start) * min(step / max(config.steps / 2, 1), 1.0)


def run_overfit(config: OverfitConfig = OverfitConfig(), views: ObjectViews | None = None,
                progress: Callable[[dict], None] | None = None, cancel: Callable[[], bool] | None = None) -> OverfitResult:
    torch.manual_seed(config.seed)
    views = views if views is not None else render_training_views(config)
    model = LIRM(preset(config.preset)).train()
    optimiser = torch.optim.AdamW(model.parameters(), lr=config.learning_rate, betas=(0.9, 0.95), weight_decay=0.0)
    batch = views.view_batch()
    targets = RayTargets.from_views(views)
    generator = torch.Generator().manual_seed(config.seed)
    object_rays = torch.nonzero(targets.mask > 0.5)[:, 0]
    n_object = int(config.rays_per_step * config.object_ray_fraction) if len(object_rays) else 0
    history: list[dict] = []
    train_seconds = 0.0
    skipped = 0
    for step in range(config.steps):
        if cancel is not None and cancel():
            break
        step_start = time.perf_counter()
        for group in optimiser.param_groups:
            group["lr"] = learning_rate(config, step)
        render = VolumeRenderConfig(samples_per_ray=config.samples_per_ray, beta=1.0 / inverse_beta(config, step), stratified=True,
                                    numerical_normals=False)
        # Most pixels are white background: oversampling the object's pixels spends the rays on what is to be learnt.
        index = torch.cat([object_rays[torch.randint(len(object_rays), (n_object,), generator=generator)],
                           torch.randint(len(targets), (config.rays_per_step - n_object,), generator=generator)])
        rays = targets.subset(index)
        field_ = model.decode(model.update(model.initial_state(1), batch))
        out = render_rays(field_, rays.origins, rays.directions, render, generator=generator)
        colour_loss = torch.mean((out["colour"] - rays.colour) ** 2)
        albedo_loss = torch.mean((out["albedo"] + (1.0 - out["opacity"]) - rays.albedo) ** 2)
        loss = colour_loss + config.albedo_weight * albedo_loss
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        grad_norm = torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        # A non-finite loss or gradient would poison the weights for good: skip that step instead,
        # and stop with a clear message if it keeps happening.
        if not (torch.isfinite(loss) and torch.isfinite(grad_norm)):
            skipped += 1
            if skipped > config.max_skipped_steps:
                raise FloatingPointError(f"training diverged: {skipped} steps with non-finite loss or gradients (last at step {step + 1})")
            continue
        optimiser.step()
        train_seconds += time.perf_counter() - step_start
        record = {"step": step + 1, "loss": loss.item(), "colour_loss": colour_loss.item(), "albedo_loss": albedo_loss.item()}
        if config.eval_every and ((step + 1) % config.eval_every == 0 or step + 1 == config.steps):
            scores = evaluate(model, views, config, inverse_beta(config, step))
            record.update(psnr=float(np.mean(scores[0])), albedo_psnr=float(np.mean(scores[1])))
        history.append(record)
        if progress:
            progress(record)
    renders: list[dict] = []
    psnrs, albedo_psnrs = evaluate(model, views, config, inverse_beta(config, config.steps), renders)
    return OverfitResult(asdict(config), history, psnrs, albedo_psnrs, train_seconds, train_seconds / max(len(history), 1), renders)


@torch.no_grad()
def evaluate(model: LIRM, views: ObjectViews, config: OverfitConfig, inv_beta: float,
             renders: list[dict] | None = None) -> tuple[list[float], list[float]]:
    """Full renders of the input views: PSNR of colour over white, albedo PSNR on the true mask."""
    was_training = model.training
    model.eval()
    field_ = model.decode(model.update(model.initial_state(1), views.view_batch()))
    render = VolumeRenderConfig(samples_per_ray=config.eval_samples_per_ray, beta=1.0 / inv_beta, numerical_normals=False)
    psnrs, albedo_psnrs = [], []
    for i, camera in enumerate(views.cameras):
        out = render_camera(field_, camera, render)
        if renders is not None:
            renders.append({"colour": out["colour"], "albedo": out["albedo"], "opacity": out["opacity"]})
        psnrs.append(psnr(np.clip(out["colour"], 0, 1), views.image[i]))
        inside = views.mask[i] > 0.99
        coverage = views.mask[i][..., None]
        true_albedo = views.albedo[i] / np.maximum(coverage, 1e-6)
        albedo_psnrs.append(scaled_albedo_psnr(out["albedo"], true_albedo, inside))
    model.train(was_training)
    return psnrs, albedo_psnrs


def comparison_sheet(views: ObjectViews, result: OverfitResult) -> np.ndarray:
    """Rows: true image, rendered colour, true albedo, rendered albedo (sRGB-encoded, over white);
    one column per input view."""
    rows = [[], [], [], []]
    for i, render in enumerate(result.renders):
        coverage = views.mask[i][..., None]
        true_albedo = views.albedo[i] + (1.0 - coverage)
        albedo = render["albedo"] * render["opacity"][..., None] + (1.0 - render["opacity"][..., None])
        for row, image in zip(rows, (views.image[i], render["colour"], true_albedo ** (1 / 2.2), albedo ** (1 / 2.2))):
            row.append(np.clip(image, 0.0, 1.0))
    return np.concatenate([np.concatenate(row, axis=1) for row in rows], axis=0)
