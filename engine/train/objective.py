"""One training iteration as a module: `update_sets` progressive updates of the same reconstruction
state, each followed by rendering the target crops and the losses (the supplementary: "2 then 3
update sets per iteration with the loss after each update"). The loss is the mean over updates.

Wrapping the whole iteration in one nn.Module is what lets DistributedDataParallel see a single
forward per backward although the network runs several updates inside it.

`render_checkpointing` (on GPUs in training) keeps no activations of a scene's rendered crops: each
scene's render and losses run again in the backward pass. The crops' samples are nearly all of a
step's memory (an H200 slice measured a 110 GiB peak at 16 scenes of `small`, stage 1, where the
network's own activations were 6.5 GiB of it), so this is what lets a step fit an 80 GB GPU, for the
price of rendering the crops twice. The stratified samples are drawn again from the same generator
state, so the gradients are the ones without it (tested).
"""

from __future__ import annotations

import torch
from torch import nn
from torch.profiler import record_function
from torch.utils.checkpoint import checkpoint

from lirm.engine.model.lirm import LIRM, ViewBatch
from lirm.engine.model.occupancy_grid import OccupancyConfig, OccupancyGrid
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_rays

from .losses import LossWeights, map_losses


class TrainingObjective(nn.Module):
    def __init__(self, model: LIRM, weights: LossWeights, perceptual: nn.Module | None, render_checkpointing: bool = False):
        super().__init__()
        self.model = model
        self.weights = weights
        self.perceptual = perceptual
        self.render_checkpointing = render_checkpointing

    def forward(self, inputs: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]],
                targets: list[list[dict[str, torch.Tensor]]], crop: int, render: VolumeRenderConfig,
                occupancy: OccupancyConfig | None = None,
                generator: torch.Generator | None = None) -> tuple[torch.Tensor, dict[str, float]]:
        model = self.model
        batch = inputs[0][0].shape[0]
        state = model.initial_state(batch)
        total = 0.0
        # The logged terms stay on the device until the end: one synchronisation per step, not one
        # per scene and term (on a GPU each would stall the queue of kernels).
        logged: dict[str, torch.Tensor] = {}
        for u, (image, image_bg, plucker) in enumerate(inputs):
            with record_function("update"):
                state = model.update(state, ViewBatch(image, image_bg, plucker))
            with record_function("decode"):
                field = model.decode(state)
            update_loss = 0.0
            for b in range(batch):
                scene_field = field.item(b)
                t = targets[u][b]
                grid = None
                if occupancy is not None:
                    step = 2.0 * model.config.radius / render.samples_per_ray
                    grid = OccupancyGrid.build(scene_field, model.config.radius, render.beta, step, occupancy)
                with record_function("render_and_losses"):
                    terms = self._scene_terms(scene_field, t, crop, render, grid, generator)
                update_loss = update_loss + sum(terms.values()) / batch
                for name, value in terms.items():
                    logged[name] = logged.get(name, 0.0) + value.detach().float() / (batch * len(inputs))
            logged[f"loss_update{u + 1}"] = update_loss.detach().float()
            total = total + update_loss / len(inputs)
        names = list(logged)
        values = torch.stack([logged[name] for name in names]).tolist()
        return total, dict(zip(names, values))

    def _scene_terms(self, scene_field, targets: dict[str, torch.Tensor], crop: int, render: VolumeRenderConfig,
                     grid: OccupancyGrid | None, generator: torch.Generator | None) -> dict[str, torch.Tensor]:
        def terms_of(start_state: torch.Tensor | None) -> tuple[dict[str, torch.Tensor], torch.Generator | None]:
            local = generator
            if start_state is not None:  # a private copy at the given state: the recompute draws the same samples
                local = torch.Generator(generator.device)
                local.set_state(start_state)
            out = render_rays(scene_field, targets["origins"], targets["directions"], render, grid=grid, generator=local)
            return map_losses(out, targets, crop, self.weights, self.perceptual), local

        if not (self.render_checkpointing and torch.is_grad_enabled()):
            return terms_of(None)[0]
        start = generator.get_state() if generator is not None else None
        names: list[str] = []
        after: list[torch.Generator | None] = []

        def stacked() -> torch.Tensor:
            terms, local = terms_of(start)
            names[:] = list(terms)
            after[:] = [local]
            return torch.stack([value.float() for value in terms.values()])

        values = checkpoint(stacked, use_reentrant=False)  # the default generator's state is kept by checkpoint itself
        if generator is not None:  # on, as if the samples had been drawn from it
            generator.set_state(after[0].get_state())
        return dict(zip(names, values.unbind(0)))
