"""One training iteration's data for one process: `update_sets` sets of input views per scene (the
network sees them one update at a time) and, after each update, random crops of target views with
their rays and ground-truth maps (the supplementary's supervision crops at the stage's GT
resolution).

Everything random here comes from a generator seeded by (data seed, step, rank): the data of a step
does not depend on what ran before it, which is what makes a resumed run continue the same curve.
"""

from __future__ import annotations

from dataclasses import dataclass

import logging

import cv2
import numpy as np
import torch

from lirm.engine.synth.object_views import ObjectViews
from lirm.engine.synth.view_crops import scale_pixels

from .scene_source import SceneRenderError, SceneSource
from .stages import StageConfig

log = logging.getLogger(__name__)

PIXEL_SCALE = (0.75, 1.25)  # supplementary: on-the-fly perturbation of the image pixels
TARGET_MAPS = ("colour", "albedo", "roughness", "metallic", "normal", "mask")
MAX_SCENE_FAILURES = 20  # consecutive scenes that fail to render before giving up


@dataclass
class TrainingSample:
    step: int
    scene_seeds: list[int]
    crop: int
    # Per update u: inputs[u] = (image, image_bg, plucker), each (B, V_u, C, S, S).
    inputs: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]
    # Per update u and scene b: targets[u][b][name] = (T * crop * crop, C) rays and maps in crop order.
    targets: list[list[dict[str, torch.Tensor]]]


def step_generator(data_seed: int, step: int, rank: int) -> np.random.Generator:
    return np.random.default_rng([int(data_seed), int(step), int(rank)])


def draw_scene_seed(rng: np.random.Generator, scene_pool: int) -> int:
    """From a pool of `scene_pool` scenes (reused, worth caching), or any seed when the pool is 0."""
    return int(rng.integers(0, scene_pool)) if scene_pool > 0 else int(rng.integers(0, 2**31 - 1))


def make_sample(source: SceneSource, stage: StageConfig, step: int, rank: int, scenes_here: int,
                data_seed: int, scene_pool: int) -> TrainingSample:
    rng = step_generator(data_seed, step, rank)
    scenes, seeds = [], []
    failures = 0
    while len(scenes) < scenes_here:
        seed = draw_scene_seed(rng, scene_pool)
        if seed in source.failed_seeds:
            continue
        try:
            scenes.append(scale_pixels(source.scene(seed), float(rng.uniform(*PIXEL_SCALE))))
            seeds.append(seed)
        except SceneRenderError as err:
            failures += 1
            log.warning("%s; skipping it", err)
            if failures > MAX_SCENE_FAILURES:
                raise RuntimeError(f"{failures} training scenes in a row failed to render (last: {err}); "
                                   f"check the model and environment folders") from err
    sizes = [int(rng.integers(stage.views_per_set[0], stage.views_per_set[1] + 1)) for _ in range(stage.update_sets)]
    inputs_per_scene, targets = [], [[] for _ in range(stage.update_sets)]
    for views in scenes:
        n = len(views.cameras)
        order = rng.permutation(n)
        if sum(sizes) > n:
            raise ValueError(f"{stage.update_sets} sets of up to {max(sizes)} inputs need {sum(sizes)} views; scenes have {n}")
        starts = np.cumsum([0] + sizes)
        inputs_per_scene.append([order[starts[u]:starts[u + 1]] for u in range(stage.update_sets)])
        for u in range(stage.update_sets):
            chosen = rng.choice(n, size=min(stage.targets_per_update, n), replace=False)
            targets[u].append(_target_crops(views, chosen, stage.target_resolution, stage.crop, rng))
    inputs = []
    for u in range(stage.update_sets):
        per_scene = [_input_arrays(views, idx[u]) for views, idx in zip(scenes, inputs_per_scene)]
        inputs.append(tuple(torch.from_numpy(np.stack([p[k] for p in per_scene])) for k in range(3)))
    return TrainingSample(step, seeds, stage.crop, inputs, targets)


def _input_arrays(views: ObjectViews, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V, C, S, S) float32 image, background and Plücker arrays of the chosen views."""
    def chw(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a.transpose(0, 3, 1, 2), dtype=np.float32)

    plucker = np.stack([views.cameras[i].plucker() for i in idx])
    return chw(views.image[idx]), chw(views.image_bg[idx]), chw(plucker)


def _target_crops(views: ObjectViews, chosen: np.ndarray, resolution: int, crop: int,
                  rng: np.random.Generator) -> dict[str, torch.Tensor]:
    """Each chosen view resized to the GT resolution, then a random crop x crop window of it."""
    maps: dict[str, list[np.ndarray]] = {name: [] for name in TARGET_MAPS + ("origins", "directions")}
    crop = min(crop, resolution)
    for i in chosen:
        camera = views.cameras[i].resized(resolution, resolution)
        x0, y0 = (int(v) for v in rng.integers(0, resolution - crop + 1, size=2))
        window = camera.crop_resize(x0, y0, crop, crop, crop, crop)
        origins, directions = window.pixel_rays()
        maps["origins"].append(origins)
        maps["directions"].append(directions)
        sources = {"colour": views.image[i], "albedo": views.albedo[i], "roughness": views.roughness[i],
                   "metallic": views.metallic[i], "normal": views.normal[i], "mask": views.mask[i]}
        for name, full in sources.items():
            resized = full if full.shape[0] == resolution else cv2.resize(full, (resolution, resolution), interpolation=cv2.INTER_AREA)
            maps[name].append(resized[y0:y0 + crop, x0:x0 + crop])
    out = {}
    for name, parts in maps.items():
        a = np.stack(parts).astype(np.float32)
        out[name] = torch.from_numpy(a.reshape(-1, a.shape[-1]) if a.ndim == 4 else a.reshape(-1))
    return out
