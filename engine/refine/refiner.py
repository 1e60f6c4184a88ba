"""The refinement loop: Adam on the field's planes, panoramas and heads against batches of rays from
every view, within a time budget, coarse to fine, keeping the best state.

Schedules run on the share of the budget spent (time, or iterations when no time is set): the plane
resolution steps through `plane_resolutions` at equal shares, 1/beta rises linearly to its final value
at `beta_ramp`, and the learning rates decay by a cosine to `final_lr_fraction`. Ctrl-C (or the
`cancel` callback) stops the loop and the best state so far is kept: best by the running mean of the
batch loss, checked every `best_every` steps.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable

import torch

from lirm.engine.model.occupancy_grid import OccupancyGrid

from .config import RefineConfig
from .image_materials import pixel_material_targets
from .objective import batch_loss
from .outside_bounds import OutsideBounds
from .ray_rendering import render_ray_batch, with_sdf_normals
from .refinable_field import RefinableField
from .refine_views import RefineViews
from .unseen_floor import UnseenFloor


@dataclass
class RefineTick:
    """What the progress callback sees after a step."""

    step: int
    fraction: float  # of the budget spent
    elapsed: float  # seconds
    eta: float  # seconds left (the budget's, or the iterations' at the current pace)
    loss: float  # running mean
    psnr: float  # of the batch colours, from the running mean squared error
    resolution: int
    inv_beta: float


@dataclass
class RefineResult:
    field: RefinableField  # holding the best state
    steps: int
    seconds: float
    best_step: int
    best_loss: float
    stopped: str  # "budget", "iterations" or "cancelled"
    history: list[dict] = field(default_factory=list)  # every `best_every` steps: step, seconds, loss, terms
    lighting: object | None = None  # the fitted PanoramaLighting (inverse rendering), at the best state
    # Whether the image-space material network was listened to, and why ("": the fit never asked it).
    material_network: str = ""


def _optimiser(refinable: RefinableField, config: RefineConfig, lighting=None) -> torch.optim.Optimizer:
    groups = [{"params": [refinable.planes], "lr": config.plane_lr, "base_lr": config.plane_lr},
              {"params": list(refinable.heads.parameters()), "lr": config.head_lr, "base_lr": config.head_lr}]
    if refinable.panoramas is not None:
        groups.append({"params": [refinable.panoramas], "lr": config.nde_lr, "base_lr": config.nde_lr})
    if lighting is not None and list(lighting.parameters()):  # a fixed (known) lighting has nothing to fit
        groups.append({"params": list(lighting.parameters()), "lr": config.lighting_lr, "base_lr": config.lighting_lr})
    # fused: one kernel over each tensor instead of a dozen passes; the planes' 3.5M values at 192² took
    # 10.4 ms a step with the default implementation and 3.1 ms fused on the 2-core CPU (README).
    return torch.optim.Adam(groups, betas=(0.9, 0.99), eps=1e-15, fused=True)


def _material_anchor(start, device: torch.device) -> Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]:
    """points -> (roughness, metallic) of the field the fit started from, held fixed."""
    start.planes = start.planes.to(device)
    start.heads.to(device)

    @torch.no_grad()
    def anchor(points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        sample = start.sample(points[None])
        return sample.roughness[0], sample.metallic[0]

    return anchor


def _volume_points(grid: OccupancyGrid | None, config: RefineConfig, generator: torch.Generator,
                   device: torch.device) -> torch.Tensor:
    """Points spread uniformly over the sampling grid's occupied voxels (the whole bounding cube
    without a grid), for the volume term."""
    count = config.eikonal_points
    if grid is None:
        return (torch.rand(count, 3, generator=generator) * 2.0 - 1.0).to(device)
    return grid.points_in_voxels(grid.occupied.nonzero(), count, generator).to(device)


def _stage(fraction: float, stages: int) -> int:
    return min(int(fraction * stages), stages - 1)


def refine_field(refinable: RefinableField, views: RefineViews, config: RefineConfig, grid: OccupancyGrid | None,
                 progress: Callable[[RefineTick], None] | None = None,
                 cancel: Callable[[], bool] | None = None,
                 live: Callable[[RefinableField], None] | None = None, live_every: float = 5.0,
                 lighting=None, start_has_materials: bool = False) -> RefineResult:
    """`live`, when given, is called with the field as it is every `live_every` seconds (the app shows
    it while the fit runs). `lighting` (a PanoramaLighting), with config.inverse_rendering, turns on
    the inverse rendering of the materials, fitting the lighting with them. `start_has_materials`: the
    starting field's roughness and metallic are a prediction (a LIRM state or an earlier refinement),
    so that with config.anchor_materials the material prior holds the field to them instead of to
    constants; starts that know nothing of materials (the hull, scratch) leave it False."""
    device = torch.device(config.device)
    refinable.to(device)
    if not config.inverse_rendering:
        lighting = None
    if lighting is not None:
        lighting.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    if config.rays_through_hull and grid is not None:
        views = views.through_grid(grid, refinable.config.radius)
    budget = None if config.minutes is None else 60.0 * config.minutes
    resolutions = config.plane_resolutions
    anchor = _material_anchor(refinable.frozen_field(), device) if start_has_materials and config.anchor_materials else None
    floor = UnseenFloor(grid, refinable.config.radius) if config.losses.floor else None
    outside = OutsideBounds(grid) if config.losses.outside_bounds and grid is not None else None
    material_targets, material_network = None, ""
    if lighting is not None and config.losses.reads_material_network and config.material_network != "off":
        material_targets, material_network = pixel_material_targets(views.images, views.masks, config.material_net or None,
                                                                    check_familiarity=config.material_network == "auto")
    refinable.resample_planes(resolutions[0])
    optimiser = _optimiser(refinable, config, lighting)
    stage = 0
    ema_loss = ema_mse = None
    best = (math.inf, 0, refinable.snapshot())
    best_inv_beta = inv_beta = config.inv_beta[0]
    best_lighting = None if lighting is None else {k: v.detach().clone() for k, v in lighting.state_dict().items()}
    history: list[dict] = []
    start = time.perf_counter()
    step, stopped = 0, "iterations"
    last_live = start
    try:
        while step < config.iterations:
            elapsed = time.perf_counter() - start
            fraction = max(step / config.iterations, elapsed / budget if budget else 0.0)
            if fraction >= 1.0:
                stopped = "budget"
                break
            if cancel is not None and cancel():
                stopped = "cancelled"
                break
            wanted = _stage(fraction, len(resolutions))
            if wanted != stage:
                stage = wanted
                refinable.resample_planes(resolutions[stage])
                optimiser = _optimiser(refinable, config, lighting)
                # The best state so far was at a coarser resolution; compare afresh from here.
                best = (math.inf, best[1], best[2])
                ema_loss = None
            inv_beta = config.inv_beta[0] + (config.inv_beta[1] - config.inv_beta[0]) * min(fraction / config.beta_ramp, 1.0)
            decay = config.final_lr_fraction + (1.0 - config.final_lr_fraction) * 0.5 * (1.0 + math.cos(math.pi * fraction))
            for group in optimiser.param_groups:
                group["lr"] = group["base_lr"] * decay

            shading = lighting if lighting is not None and fraction >= config.pbr_start else None
            pairs = None
            if shading is not None and config.losses.albedo_pairs:
                # A share of the batch comes as neighbours of the rest (same number of rays in all).
                count = int(config.rays_per_step * config.pair_fraction)
                index = views.sample_rays(config.rays_per_step - count, config.edge_ray_fraction, generator)
                anchors = torch.arange(count) % (index.shape[0])
                index = torch.cat([index, views.neighbours(index[anchors], config.pair_radius_px, generator)])
                pairs = torch.stack([anchors, torch.arange(count) + (index.shape[0] - count)], dim=1).to(device)
            else:
                index = views.sample_rays(config.rays_per_step, config.edge_ray_fraction, generator)
            origins, directions = views.origins[index].to(device), views.directions[index].to(device)
            colours, alphas = views.colours[index].to(device), views.alphas[index].to(device)
            field_ = refinable.field()
            # Roughness and metallic along the rays only where a loss reads them there.
            materials = shading is not None or (anchor is None and config.losses.material_prior > 0)
            render = render_ray_batch(field_, origins, directions, grid, 1.0 / inv_beta, config.coarse_samples,
                                      config.fine_samples, generator, materials=materials,
                                      prune_weight=config.appearance_weight)
            if shading is not None and config.shading_normal in ("sdf", "sdf-fixed"):
                render = with_sdf_normals(field_, render, origins, directions, shape_surface=config.shading_normal == "sdf",
                                          pixel_angles=views.pixel_angles[index].to(device) if config.footprint_roughness else None)
            if floor is not None:
                floor.observe(origins, directions, render.depth, render.opacity.detach(), alphas,
                              views.pixel_angles[index].to(device), 1.0 / inv_beta)
            carve = floor is not None and fraction >= config.floor_start
            loss, terms = batch_loss(field_, render, colours, alphas, config.losses, config.eikonal_points, generator,
                                     shading, directions, anchor,
                                     _volume_points(grid, config, generator, device) if config.losses.volume else None,
                                     floor, floor.points_below(config.eikonal_points, generator, device) if carve else None,
                                     pairs, outside.points(config.eikonal_points // 2, generator, device) if outside else None,
                                     material_targets[index].to(device) if material_targets is not None else None)
            optimiser.zero_grad(set_to_none=True)
            loss.backward()
            optimiser.step()
            step += 1

            mse = float(((render.colour.detach() - colours) ** 2).mean())
            value = float(loss.detach())
            ema_loss = value if ema_loss is None else 0.9 * ema_loss + 0.1 * value
            ema_mse = mse if ema_mse is None else 0.9 * ema_mse + 0.1 * mse
            if step % config.best_every == 0:
                history.append({"step": step, "seconds": round(time.perf_counter() - start, 2), "loss": ema_loss,
                                "resolution": refinable.resolution, "inv_beta": inv_beta, **terms,
                                **({"floor_height": floor.height} if floor is not None and floor.height is not None else {})})
                # Only the last resolution's states are candidates: an earlier, coarser best would
                # throw away the detail the finer planes are there for.
                if ema_loss < best[0] and stage == len(resolutions) - 1:
                    best = (ema_loss, step, refinable.snapshot())
                    best_inv_beta = inv_beta
                    if lighting is not None:
                        best_lighting = {k: v.detach().clone() for k, v in lighting.state_dict().items()}
            if live is not None and time.perf_counter() - last_live >= live_every:
                live(refinable)
                last_live = time.perf_counter()
            if progress is not None:
                elapsed = time.perf_counter() - start
                fraction = max(step / config.iterations, elapsed / budget if budget else 0.0)
                eta = max(budget - elapsed, 0.0) if budget else elapsed / step * (config.iterations - step)
                if budget:
                    eta = min(eta, elapsed / step * (config.iterations - step))
                progress(RefineTick(step, min(fraction, 1.0), elapsed, eta, ema_loss, -10.0 * math.log10(max(ema_mse, 1e-10)),
                                    refinable.resolution, inv_beta))
    except KeyboardInterrupt:
        stopped = "cancelled"
    seconds = time.perf_counter() - start
    if step and (not history or history[-1]["step"] != step) and ema_loss is not None:
        history.append({"step": step, "seconds": round(seconds, 2), "loss": ema_loss, "resolution": refinable.resolution})
    best_loss, best_step, snapshot = best
    if best_step == 0 or math.isinf(best_loss):
        # No candidate at the last resolution yet (a short or cancelled run): the latest state is the best known.
        best_step, best_loss = step, (ema_loss if ema_loss is not None else math.inf)
        best_inv_beta = inv_beta
    else:
        refinable.load_snapshot(snapshot)
        if lighting is not None and best_lighting is not None:
            lighting.load_state_dict(best_lighting)
    refinable.fitted_beta = 1.0 / best_inv_beta
    return RefineResult(refinable, step, seconds, best_step, best_loss, stopped, history, lighting, material_network)
