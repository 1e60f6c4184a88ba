"""The image-space material prior as a refinement term: each ray's surface materials held to what the
material network (model/material_net.py) predicts at that ray's pixel of its photo.

The photometric term alone cannot tell a gold line from a dark paint (README, "How much of the
roughness and metallic the fit knows"); the network has seen many painted and metal objects and
can. Predicted once per view before the fit, then read per ray like the photo's colour.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.model.material_net import load_material_net, predict_materials
from lirm.engine.model.material_net_familiarity import material_net_familiarity
from lirm.engine.model.pretrained import shipped_file
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS

SHIPPED_NAME = "material-net.safetensors"


def shipped_material_net() -> Path | None:
    return shipped_file(SHIPPED_NAME)


def pixel_material_targets(images: np.ndarray, masks: np.ndarray, net_path: str | Path | None = None,
                           check_familiarity: bool = False) -> tuple[torch.Tensor | None, str]:
    """(V*H*W, 5) per pixel: metallic, roughness, linear albedo, flattened in RefineViews' order, from
    the network at `net_path` or the shipped one, and a line saying so. With `check_familiarity`, None
    instead where the photos are unlike the network's training (model/material_net_familiarity.py)."""
    path = Path(net_path) if net_path else shipped_material_net()
    if path is None:
        raise LirmUserError(f"the image-space material prior is on but no network ships in resources/checkpoints/{SHIPPED_NAME}; "
                            "train one with `lirm train-materials` or turn the prior off (losses.image_metallic, image_roughness, image_albedo and image_albedo_shade at 0)")
    net, _ = load_material_net(path)
    said, maps = f"the material network used ({path.name}: on every photo, as asked)", None
    if check_familiarity:
        familiarity = material_net_familiarity(net, images, masks)
        said, maps = familiarity.describe(), familiarity.as_photographed
        if not familiarity.familiar:
            return None, said
    if maps is None:
        maps = predict_materials(net, images, masks)
    flat = np.concatenate([maps.metallic[..., None], maps.roughness[..., None], maps.albedo], axis=-1)
    return torch.from_numpy(np.ascontiguousarray(flat.reshape(-1, 5), dtype=np.float32)), said


def image_material_terms(roughness: torch.Tensor, metallic: torch.Tensor, albedo: torch.Tensor, targets: torch.Tensor,
                         with_albedo: bool, with_shade: bool = False) -> dict[str, torch.Tensor]:
    """L1 of the solid rays' (opacity-normalised) metallic and roughness against the network's; with
    `with_albedo`, also of the albedo's chromaticity (its brightness is the lighting's to share); with
    `with_shade`, of the albedo's log luminance against the network's after the batch's median
    difference is taken out (one brightness scale for the whole object stays free)."""
    terms = {"image_metallic": (metallic - targets[:, 0]).abs().mean(), "image_roughness": (roughness - targets[:, 1]).abs().mean()}
    if with_albedo:
        chroma = albedo / albedo.sum(-1, keepdim=True).clamp(min=1e-3)
        target = targets[:, 2:5] / targets[:, 2:5].sum(-1, keepdim=True).clamp(min=1e-3)
        terms["image_albedo"] = (chroma - target).abs().sum(-1).mean()
    if with_shade:
        weights = albedo.new_tensor(LUMINANCE_WEIGHTS)
        difference = (albedo @ weights).clamp(min=1e-3).log() - (targets[:, 2:5] @ weights).clamp(min=1e-3).log()
        terms["image_albedo_shade"] = (difference - difference.detach().median()).abs().mean()
    return terms
