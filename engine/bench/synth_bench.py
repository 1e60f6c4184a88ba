"""`lirm bench synth`: how fast the synthetic world renders training views on this machine, and a
contact sheet of what it makes (rows: scenes; per view the image, background image, albedo,
roughness, metallic and normal) to look at. With `capture_crops` (the default) the views are cut as
training cuts them (synth/view_crops.py), and the cut is part of the timing."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from lirm.engine.io.images import to_uint8, write_png
from lirm.engine.synth.training_scenes import TrainingScene, TrainingSceneConfig, make_training_scene
from lirm.engine.synth.view_crops import crop_like_capture


@dataclass(frozen=True)
class SynthBenchConfig:
    scenes: int = 4
    scene: TrainingSceneConfig = field(default_factory=lambda: replace(TrainingSceneConfig(), views=8))
    first_seed: int = 0
    sheet_views: int = 4  # views per scene on the contact sheet
    sheet_path: Path | None = None
    capture_crops: bool = True  # cut each view around the object like the capture pipeline (what training sees)


@dataclass
class SynthBenchResult:
    scenes: int
    views: int
    size: int
    seconds: float
    views_per_second: float
    descriptions: list[dict]
    sheet: Path | None

    def table(self) -> str:
        return (f"{self.scenes} scenes x {self.views // max(self.scenes, 1)} views of {self.size}x{self.size}: "
                f"{self.seconds:.1f} s, {self.views_per_second:.2f} views per second (with the full G-buffer)")


def run_synth_bench(config: SynthBenchConfig, progress=None) -> SynthBenchResult:
    from dataclasses import asdict

    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    scenes: list[TrainingScene] = []
    try:
        make_training_scene(renderer, config.first_seed, replace(config.scene, views=1))  # compile shaders, bake the BRDF table
        start = time.perf_counter()
        for k in range(config.scenes):
            scene = make_training_scene(renderer, config.first_seed + k, config.scene)
            if config.capture_crops:
                scene.views = crop_like_capture(scene.views, config.scene.size)
            scenes.append(scene)
            if progress:
                progress(f"scene {k + 1}/{config.scenes}: {scenes[-1].description.object_name} under {scenes[-1].description.environment}")
        seconds = time.perf_counter() - start
    finally:
        renderer.release()
        ctx.release()
    views = config.scenes * config.scene.views
    sheet = write_png(config.sheet_path, to_uint8(contact_sheet(scenes, config.sheet_views))) if config.sheet_path else None
    return SynthBenchResult(config.scenes, views, config.scene.size, seconds, views / max(seconds, 1e-9),
                            [asdict(s.description) for s in scenes], sheet)


def contact_sheet(scenes: list[TrainingScene], views_per_scene: int) -> np.ndarray:
    rows = []
    for scene in scenes:
        v = scene.views
        tiles = []
        for i in range(min(views_per_scene, len(v.cameras))):
            mask = v.mask[i][..., None]
            tiles += [v.image[i], v.image_bg[i], np.clip(v.albedo[i] + (1 - mask), 0, 1) ** (1 / 2.2),
                      np.repeat(v.roughness[i][..., None], 3, -1), np.repeat(v.metallic[i][..., None], 3, -1),
                      (0.5 * v.normal[i] + 0.5) * mask]
        rows.append(np.concatenate(tiles, axis=1))
    return np.concatenate(rows, axis=0)
