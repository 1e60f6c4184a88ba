"""Training the image-space material prior (model/material_net.py) on the CPU.

The data are the training scenes of synth/training_scenes.py (the same generator, seeds and
augmentations the LIRM prior trains on; the held-out sets' variants are never drawn), optionally with
scenes of varied materials and shapes after them (synth/material_variety.py: objects without metal,
all-metal ones, blobs and tori, re-rigged lighting; measured, and off by default), rendered as whole
frames at the working size with a field of view near the protocol's, each view with its true albedo,
roughness and metallic. Losses on the object's pixels: binary cross-entropy of the metallic,
L1 of the roughness and of the linear albedo.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Callable

import numpy as np
import torch
import torch.nn.functional as F

from lirm.engine.model.material_net import WORKING_SIZE, MaterialNet, MaterialNetConfig, network_input, object_exposure
from lirm.engine.synth.material_variety import make_varied_scene
from lirm.engine.synth.training_scenes import TrainingSceneConfig, make_training_scene


MIN_STEPS = 20  # the learning-rate cycle's warm-up needs a few steps of its own


@dataclass(frozen=True)
class MaterialTrainingConfig:
    scenes: int = 500
    first_seed: int = 1000  # training scene seeds first_seed .. first_seed + scenes - 1
    # Scenes of synth/material_variety.py, seeds 0 .. varied_scenes - 1, after those. 0 by default: 500 of
    # them beside the 500 cost the network most of what it knew and taught it little (README, "Varied scenes").
    varied_scenes: int = 0
    views_per_scene: int = 8
    fov_deg: tuple[float, float] = (30.0, 70.0)  # around the protocol's 50 and a capture's tighter crops
    steps: int = 3000  # the shipped weights' length: 1500 scored 1-3 dB less on the held-out objects (MATERIAL_NET.md)
    batch: int = 12
    learning_rate: float = 2e-3
    exposure_jitter: float = 0.15  # the photo's display values scaled by U(1 - j, 1 + j): cameras differ
    seed: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class MaterialData:
    images: np.ndarray  # (N, S, S, 3) display sRGB on white
    masks: np.ndarray  # (N, S, S)
    albedo: np.ndarray  # (N, S, S, 3)
    roughness: np.ndarray  # (N, S, S)
    metallic: np.ndarray  # (N, S, S)

    def save(self, path) -> None:
        np.savez(path, **{k: getattr(self, k).astype(np.float16) for k in ("images", "masks", "albedo", "roughness", "metallic")})

    @classmethod
    def load(cls, path) -> "MaterialData":
        with np.load(path) as d:
            return cls(*(d[k].astype(np.float32) for k in ("images", "masks", "albedo", "roughness", "metallic")))


def render_material_data(config: MaterialTrainingConfig, progress: Callable[[int, int], None] | None = None) -> MaterialData:
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    scene_config = TrainingSceneConfig(views=config.views_per_scene, size=WORKING_SIZE, supersample=2, fov_deg=config.fov_deg)
    context = create_headless_context()
    renderer = PBRRenderer(context)
    maps: dict[str, list[np.ndarray]] = {k: [] for k in ("image", "mask", "albedo", "roughness", "metallic")}
    total = config.scenes + config.varied_scenes
    try:
        for k in range(total):
            if k < config.scenes:
                views = make_training_scene(renderer, config.first_seed + k, scene_config).views
            else:
                views = make_varied_scene(renderer, k - config.scenes, scene_config).views
            for name in maps:
                maps[name].append(getattr(views, name).astype(np.float16))
            if progress:
                progress(k + 1, total)
    finally:
        renderer.release()
        context.release()
    return MaterialData(*(np.concatenate(maps[k]).astype(np.float32) for k in ("image", "mask", "albedo", "roughness", "metallic")))


def material_loss(logits: torch.Tensor, mask: torch.Tensor, albedo: torch.Tensor, roughness: torch.Tensor,
                  metallic: torch.Tensor) -> tuple[torch.Tensor, dict[str, float]]:
    """Masked losses; `mask` (B, H, W) weights each pixel by its coverage."""
    weight = mask / mask.sum().clamp(min=1.0)
    metal = F.binary_cross_entropy_with_logits(logits[:, 0], metallic, reduction="none")
    rough = (torch.sigmoid(logits[:, 1]) - roughness).abs()
    colour = (torch.sigmoid(logits[:, 2:5]) - albedo.permute(0, 3, 1, 2)).abs().mean(1)
    terms = {"metallic": (metal * weight).sum(), "roughness": (rough * weight).sum(), "albedo": (colour * weight).sum()}
    return sum(terms.values()), {k: float(v.detach()) for k, v in terms.items()}


def train_material_net(data: MaterialData, config: MaterialTrainingConfig, net_config: MaterialNetConfig = MaterialNetConfig(),
                       progress: Callable[[int, dict], None] | None = None,
                       cancelled: Callable[[], bool] | None = None) -> tuple[MaterialNet, list[dict]]:
    """The network trained for config.steps (fewer if `cancelled` says so), and its loss history."""
    if config.steps < MIN_STEPS:
        raise ValueError(f"the material network trains for at least {MIN_STEPS} steps, got {config.steps}")
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    net = MaterialNet(net_config)
    optimiser = torch.optim.AdamW(net.parameters(), lr=config.learning_rate, weight_decay=1e-4)
    # One cycle: a warm-up over the first 5% (at least 3 steps), then a cosine down (the shipped weights' schedule).
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimiser, config.learning_rate, total_steps=config.steps,
                                                   pct_start=max(0.05, 3.0 / config.steps))
    count = len(data.masks)
    history = []
    start = time.perf_counter()
    net.train()
    for step in range(config.steps):
        if cancelled is not None and cancelled():
            break
        pick = rng.integers(0, count, config.batch)
        images = data.images[pick]
        masks = data.masks[pick]
        gain = rng.uniform(1.0 - config.exposure_jitter, 1.0 + config.exposure_jitter, (config.batch, 1, 1, 1))
        images = object_exposure(images, masks, gain)
        maps = [data.albedo[pick], data.roughness[pick], data.metallic[pick]]
        flip = rng.uniform(size=config.batch) < 0.5
        images, masks = _flip(images, flip), _flip(masks, flip)
        maps = [_flip(m, flip) for m in maps]
        logits = net(network_input(images, masks))
        loss, terms = material_loss(logits, torch.from_numpy(masks), *(torch.from_numpy(np.ascontiguousarray(m)) for m in maps))
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
        schedule.step()
        record = {"step": step + 1, "loss": float(loss.detach()), **terms, "seconds": time.perf_counter() - start}
        history.append(record)
        if progress:
            progress(step + 1, record)
    net.eval()
    return net, history


def _flip(a: np.ndarray, flip: np.ndarray) -> np.ndarray:
    out = a.copy()
    out[flip] = a[flip][:, :, ::-1]
    return out


def heldout_material_scores(net: MaterialNet, objects) -> list[dict]:
    """The network's own materials on held-out objects' input views (evaluation/heldout_sets.py), against
    the truth's on the object's pixels: metallic and roughness PSNR, albedo PSNR after Stanford-ORB's
    per-channel scale, and the same metallic PSNR for 'no metal anywhere' as its floor."""
    from lirm.engine.metrics import psnr, scaled_albedo_psnr
    from lirm.engine.model.material_net import predict_materials

    rows = []
    for obj in objects:
        views = obj.views.select([i for s in obj.protocol.input_sets for i in s])
        maps = predict_materials(net, views.image, views.mask)
        inside = views.mask > 0.5
        rows.append({"object": obj.name, "metallic_psnr": psnr(maps.metallic, views.metallic, inside),
                     "metallic_psnr_none": psnr(np.zeros_like(views.metallic), views.metallic, inside),
                     "roughness_psnr": psnr(maps.roughness, views.roughness, inside),
                     "albedo_psnr": scaled_albedo_psnr(maps.albedo, views.albedo, inside)})
    return rows
