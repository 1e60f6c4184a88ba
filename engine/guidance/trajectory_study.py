"""The camera-trajectory study (supplementary figure 2), extended with our guidance: does choosing the
next views by coverage and uncertainty reconstruct better than random or sequential choices?

Per held-out object, the 16 protocol input views are the pool, ordered by azimuth. Update 1 uses the
first 4 in that order for every strategy (one side of the object, the case where the next choice
matters most). Updates 2 and 3 then take 4 more views each, chosen
- sequentially: the next 4 in azimuth order (the supplementary's sequential trajectory);
- at random: 4 of the remaining, seeded per object;
- guided: greedily by next-view guidance on the current reconstruction (its mesh, weighted by the
  model's uncertainty), restricted to the remaining pool views, as a photographer would be told;
  once no view adds coverage, the rest as far as possible from every view so far.
After each update the 12 output views are scored exactly as `lirm eval` scores them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import torch
import trimesh

from lirm.engine.evaluation.evaluate import (EvalConfig, EvalResult, model_device, model_inputs, score_field,
                                             update_scores)
from lirm.engine.evaluation.heldout_sets import HeldoutObject

from .coverage import SurfaceCoverage
from .next_views import camera_angles, farthest_views, greedy_views
from .suggest import field_surface
from .uncertainty import guidance_weights, vertex_uncertainty

STRATEGIES = ("guided", "random", "sequential")


@dataclass(frozen=True)
class TrajectoryConfig:
    updates: int = 3
    views_per_update: int = 4
    mesh_resolution: int = 48  # the guidance surface, as `lirm suggest` extracts it (coarse is enough)
    uncertainty: bool = True  # guided views weigh coverage by the model's uncertainty (False: coverage alone)
    seed: int = 0
    eval: EvalConfig = field(default_factory=EvalConfig)


def azimuth_order(obj: HeldoutObject) -> list[int]:
    """The object's input views sorted by azimuth, then elevation: the sequential sweep."""
    pool = sorted({i for s in obj.protocol.input_sets for i in s})
    angles = {i: camera_angles(obj.views.cameras[i]) for i in pool}
    return sorted(pool, key=lambda i: (round(angles[i][0], 3), angles[i][1]))


def guided_choice(gl, fields: list, obj: HeldoutObject, used: list[int], remaining: list[int], k: int,
                  resolution: int = 48, uncertainty: bool = True) -> list[int]:
    mesh, _ = field_surface(fields[-1], resolution, face_budget=3000)  # no surface yet: the bounding sphere
    weights = (guidance_weights(vertex_uncertainty(fields, mesh.vertices, mesh.vertex_normals)["total"])
               if uncertainty else None)
    coverage = SurfaceCoverage(gl, mesh.vertices, mesh.faces, mesh.vertex_normals)
    try:
        cameras = obj.views.cameras
        chosen, _, _ = greedy_views(coverage, [cameras[i] for i in used], [cameras[i] for i in remaining], k, weights)
    finally:
        coverage.release()
    # Nothing left to gain (all of the surface covered): the rest spread out, as far as possible from
    # every view so far, instead of bunching next to them.
    spread = farthest_views([cameras[i] for i in used], [cameras[i] for i in remaining], k - len(chosen), tuple(chosen))
    return [remaining[i] for i in chosen + spread]


def choose_views(strategy: str, gl, fields: list, obj: HeldoutObject, used: list[int], remaining: list[int], k: int,
                 rng: np.random.Generator, resolution: int = 48, uncertainty: bool = True) -> list[int]:
    if strategy == "sequential":
        return remaining[:k]
    if strategy == "random":
        return [remaining[i] for i in sorted(rng.choice(len(remaining), size=min(k, len(remaining)), replace=False))]
    if strategy == "guided":
        return guided_choice(gl, fields, obj, used, remaining, k, resolution, uncertainty)
    raise ValueError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}")


def true_surface_coverage(gl, obj: HeldoutObject, samples: int = 4000) -> SurfaceCoverage | None:
    """Coverage of the object's true surface (area-uniform samples), to say what each trajectory saw."""
    if obj.mesh is None:
        return None
    vertices, faces = obj.mesh
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    points, face_index = trimesh.sample.sample_surface(mesh, samples, seed=0)
    return SurfaceCoverage(gl, vertices, faces, mesh.vertex_normals, points=points, point_normals=mesh.face_normals[face_index])


@dataclass
class TrajectoryResult:
    scores: EvalResult  # the paper's metrics after each update
    coverage: list[float]  # mean share of the true surface seen well by the inputs so far, after each update


@torch.no_grad()
def run_trajectory_study(model, objects: list[HeldoutObject], gl, config: TrajectoryConfig = TrajectoryConfig(),
                         strategies: tuple[str, ...] = STRATEGIES,
                         progress: Callable[[str, int, int], None] | None = None) -> dict[str, TrajectoryResult]:
    """Per strategy, the paper's metrics after each update (mean over objects' output views) and the
    true-surface coverage of the views chosen so far."""
    device = model_device(model)
    results = {}
    total = len(strategies) * len(objects)
    for s_index, strategy in enumerate(strategies):
        per_update: dict[int, dict[str, list[float]]] = {u: {} for u in range(1, config.updates + 1)}
        for o_index, obj in enumerate(objects):
            truth = true_surface_coverage(gl, obj)
            if progress:
                progress(f"{strategy}: {obj.name}", s_index * len(objects) + o_index, total)
            rng = np.random.default_rng([config.seed, o_index])
            order = azimuth_order(obj)
            outputs = obj.protocol.outputs[:config.eval.output_views] if config.eval.output_views else obj.protocol.outputs
            used = order[:config.views_per_update]
            state = model.initial_state(1)
            fields: list = []
            for update in range(1, config.updates + 1):
                if update > 1:
                    remaining = [i for i in order if i not in used]
                    batch = choose_views(strategy, gl, fields[-2:], obj, used, remaining, config.views_per_update, rng,
                                         config.mesh_resolution, config.uncertainty)
                    used = used + batch
                else:
                    batch = used
                if not batch:
                    break
                state = model.update(state, model_inputs(model, obj, batch, device))
                fields.append(model.decode(state))
                score_field(fields[-1], obj, outputs, config.eval, per_update[update])
                if truth is not None:
                    seen = truth.covered([obj.views.cameras[i] for i in used]) > 0
                    per_update[update].setdefault("coverage", []).append(float(seen.mean()))
            if truth is not None:
                truth.release()
        scores = EvalResult("synthetic", [o.name for o in objects], [update_scores(u, s) for u, s in per_update.items() if s],
                            "LPIPS not computed in this study")
        coverage = [float(np.mean(s["coverage"])) if s.get("coverage") else float("nan") for s in per_update.values() if s]
        results[strategy] = TrajectoryResult(scores, coverage)
    return results


def guided_margin(results: dict[str, TrajectoryResult], against: str = "random") -> list[dict[str, float | int | None]]:
    """Guided minus `against`, per update and metric (positive = guided better; CD: against - guided)."""
    rows = []
    for u, (g, r) in enumerate(zip(results["guided"].scores.rows, results[against].scores.rows)):
        diff = lambda a, b: None if a is None or b is None else a - b  # noqa: E731
        rows.append({"update": g.update, "psnr": diff(g.psnr, r.psnr), "ssim": diff(g.ssim, r.ssim),
                     "albedo_psnr": diff(g.albedo_psnr, r.albedo_psnr),
                     "roughness_psnr": diff(g.roughness_psnr, r.roughness_psnr),
                     "metallic_psnr": diff(g.metallic_psnr, r.metallic_psnr),
                     "chamfer": diff(r.chamfer, g.chamfer),
                     "coverage": diff(results["guided"].coverage[u], results[against].coverage[u])})
    return rows
