"""The training losses (paper §3.4): L2 on the rendered RGB, albedo, roughness, metallic and normal
maps, a perceptual loss on the RGB and albedo crops, and in stage 3 L2 on the numerical normals.

Maps compare the way the renderer composites them: colour and albedo over white (so both also
teach the silhouette), roughness, metallic and normals premultiplied by coverage on both sides
(the prediction by its opacity, the ground truth by its mask), so nothing is asked off the object.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn


@dataclass(frozen=True)
class LossWeights:
    colour: float = 1.0
    albedo: float = 1.0
    roughness: float = 1.0
    metallic: float = 1.0
    normal: float = 1.0
    perceptual: float = 0.5  # on RGB and on albedo (MeshLRM's LPIPS weight)
    numerical_normal: float = 0.0  # set from the stage (1 in stage 3)

    def to_dict(self) -> dict:
        return asdict(self)


def map_losses(rendered: dict[str, torch.Tensor], targets: dict[str, torch.Tensor], crop: int,
               weights: LossWeights, perceptual: nn.Module | None) -> dict[str, torch.Tensor]:
    """rendered: render_rays' output for the rays of n crops of crop x crop pixels, in crop order;
    targets: the same rays' ground truth. Returns each weighted term (the total is their sum)."""
    opacity = rendered["opacity"]
    mask = targets["mask"][:, None]
    colour = rendered["colour"]
    albedo = rendered["albedo"] + (1.0 - opacity)  # over white
    true_albedo = targets["albedo"] + (1.0 - mask)
    terms = {
        "colour": weights.colour * torch.mean((colour - targets["colour"]) ** 2),
        "albedo": weights.albedo * torch.mean((albedo - true_albedo) ** 2),
        "roughness": weights.roughness * torch.mean((rendered["roughness"] - targets["roughness"][:, None]) ** 2),
        "metallic": weights.metallic * torch.mean((rendered["metallic"] - targets["metallic"][:, None]) ** 2),
        "normal": weights.normal * torch.mean((rendered["normal"] - targets["normal"]) ** 2),
    }
    if weights.numerical_normal > 0:
        terms["numerical_normal"] = weights.numerical_normal * torch.mean((rendered["normal_numerical"] - targets["normal"]) ** 2)
    if perceptual is not None and weights.perceptual > 0:
        def image(a: torch.Tensor) -> torch.Tensor:  # (n c c, 3) -> (n, 3, c, c)
            return a.reshape(-1, crop, crop, 3).permute(0, 3, 1, 2).clamp(0.0, 1.0)

        terms["perceptual"] = weights.perceptual * (perceptual(image(colour), image(targets["colour"]))
                                                    + perceptual(image(albedo), image(true_albedo)))
    return terms
