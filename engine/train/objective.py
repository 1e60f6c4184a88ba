"""One training iteration as a module: `update_sets` progressive updates of the same reconstruction
state, each followed by rendering the target crops and the losses (the supplementary: "2 then 3
update sets per iteration with the loss after each update"). The loss is the mean over updates.

Wrapping the whole iteration in one nn.Module is what lets DistributedDataParallel see a single
forward per backward although the network runs several updates inside it.
"""

from __future__ import annotations

import torch
from torch import nn

from lirm.engine.model.lirm import LIRM, ViewBatch
from lirm.engine.model.occupancy_grid import OccupancyConfig, OccupancyGrid
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_rays

from .losses import LossWeights, map_losses


class TrainingObjective(nn.Module):
    def __init__(self, model: LIRM, weights: LossWeights, perceptual: nn.Module | None):
        super().__init__()
        self.model = model
        self.weights = weights
        self.perceptual = perceptual

    def forward(self, inputs: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]],
                targets: list[list[dict[str, torch.Tensor]]], crop: int, render: VolumeRenderConfig,
                occupancy: OccupancyConfig | None = None,
                generator: torch.Generator | None = None) -> tuple[torch.Tensor, dict[str, float]]:
        model = self.model
        batch = inputs[0][0].shape[0]
        state = model.initial_state(batch)
        total = 0.0
        logged: dict[str, float] = {}
        for u, (image, image_bg, plucker) in enumerate(inputs):
            state = model.update(state, ViewBatch(image, image_bg, plucker))
            field = model.decode(state)
            update_loss = 0.0
            for b in range(batch):
                scene_field = field.item(b)
                t = targets[u][b]
                grid = None
                if occupancy is not None:
                    step = 2.0 * model.config.radius / render.samples_per_ray
                    grid = OccupancyGrid.build(scene_field, model.config.radius, render.beta, step, occupancy)
                out = render_rays(scene_field, t["origins"], t["directions"], render, grid=grid, generator=generator)
                terms = map_losses(out, t, crop, self.weights, self.perceptual)
                update_loss = update_loss + sum(terms.values()) / batch
                for name, value in terms.items():
                    logged[name] = logged.get(name, 0.0) + float(value.detach()) / (batch * len(inputs))
            logged[f"loss_update{u + 1}"] = float(update_loss.detach())
            total = total + update_loss / len(inputs)
        return total, logged
