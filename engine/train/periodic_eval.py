"""Held-out evaluation during training (process 0): a few objects of the synthetic held-out set,
rendered once, scored after updates 1-4 every `eval_every` steps into eval.csv and TensorBoard."""

from __future__ import annotations

import csv
from pathlib import Path

from lirm.engine.evaluation.evaluate import EvalConfig, evaluate_heldout
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.model.volume_renderer import VolumeRenderConfig

COLUMNS = ["step", "update", "psnr", "ssim", "albedo_psnr", "roughness_psnr", "metallic_psnr", "chamfer"]


class PeriodicEvaluator:
    def __init__(self, path: Path, objects: int, size: int, resume_step: int):
        self.path, self.count, self.size = path, objects, size
        self.config = EvalConfig(render=VolumeRenderConfig(samples_per_ray=64, numerical_normals=False),
                                 occupancy=OccupancyConfig(resolution=64), mesh_resolution=48, chamfer_points=5000,
                                 output_views=4)
        self._objects = None
        kept = []
        if resume_step and path.is_file():
            with open(path, newline="") as f:
                kept = [r for r in csv.DictReader(f) if int(r["step"]) <= resume_step]
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, COLUMNS)
            w.writeheader()
            w.writerows(kept)

    def _heldout(self):
        if self._objects is None:
            from lirm.engine.evaluation.heldout_sets import synthetic_heldout
            from lirm.renderer.context import create_headless_context
            from lirm.renderer.pbr_renderer import PBRRenderer

            ctx = create_headless_context()
            renderer = PBRRenderer(ctx)
            try:
                self._objects = synthetic_heldout(renderer, self.count, self.size, surface_points=5000)
            finally:
                renderer.release()
                ctx.release()
        return self._objects

    def run(self, model: LIRM, step: int, writer=None) -> list[dict]:
        result = evaluate_heldout(model, self._heldout(), self.config)
        rows = []
        for r in result.rows:
            row = {"step": step, "update": r.update, "psnr": r.psnr, "ssim": r.ssim, "albedo_psnr": r.albedo_psnr,
                   "roughness_psnr": r.roughness_psnr, "metallic_psnr": r.metallic_psnr, "chamfer": r.chamfer}
            rows.append(row)
            if writer is not None:
                for key in COLUMNS[2:]:
                    if row[key] is not None:
                        writer.add_scalar(f"eval/{key}_update{r.update}", row[key], step)
        with open(self.path, "a", newline="") as f:
            csv.DictWriter(f, COLUMNS).writerows(rows)
        return rows
