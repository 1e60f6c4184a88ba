"""How much a photo pixel says about the roughness, and the network's roughness held where it says little.

Why: the photometric fit and the material network are right about the roughness on different objects
(held-out objects 0-3, roughness PSNR, the fit then the network alone: vase 16.8 / 16.2, mug 13.1 / 23.8,
toy block 14.1 / 14.1, bottle 22.0 / 14.0; README, "The roughness, held to the
network"). Holding every ray to the network (`losses.image_roughness`) took the mugs' roughness up and
the bottle's down. A pixel informs the roughness when its shaded colour changes with it: a highlight
does, a matte side lit by a broad sky hardly. So each ray is held to the network in proportion to how
little its shading changes with the roughness: `scale / (scale + sensitivity)`.

The sensitivity: the change of the shaded display colour (the same tone curve the photometric term
compares through) per unit of roughness, from one more shading at a roughness a step away, without
gradients (the weight is a measurement of the current fit, not a thing to optimise).

Measured, not adopted (`losses.image_roughness_unseen` 0 by default): the sensitivity is small on most
rays and zero below the fitted panorama's sharpest lobe, so the hold still pulled the bottle's roughness
down, and the relighting fell as with the plain hold (README).
"""

from __future__ import annotations

import torch

from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.split_sum_shading import shade

ROUGHNESS_STEP = 0.05  # the finite difference's step in roughness


@torch.no_grad()
def roughness_sensitivity(lighting, albedo: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor,
                          normal: torch.Tensor, view: torch.Tensor, shaded_display: torch.Tensor) -> torch.Tensor:
    """(N,) mean over channels of |d display colour / d roughness| at each ray's surface; the step goes
    down where the roughness is within a step of 1."""
    step = torch.where(roughness + ROUGHNESS_STEP <= 1.0, torch.full_like(roughness, ROUGHNESS_STEP),
                       torch.full_like(roughness, -ROUGHNESS_STEP))
    moved = shade(lighting, albedo, roughness + step, metallic, normal, view).radiance
    moved_display = radiance_to_display_torch(moved, lighting.camera_response)
    return (moved_display - shaded_display).abs().mean(-1) / ROUGHNESS_STEP


def unseen_roughness_term(roughness: torch.Tensor, target: torch.Tensor, sensitivity: torch.Tensor,
                          scale: float) -> torch.Tensor:
    """L1 of the roughness against the network's, each ray weighted by how little its photo says: halved
    where the sensitivity is `scale` (config.LossWeights.unseen_roughness_scale)."""
    hold = scale / (scale + sensitivity)
    return (hold * (roughness - target).abs()).mean()
