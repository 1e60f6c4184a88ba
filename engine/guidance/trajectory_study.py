"""The camera-trajectory study (supplementary figure 2), extended with our guidance: does choosing the
next views by coverage and uncertainty reconstruct better than random or sequential choices?

Per held-out object, the 16 protocol input views are the pool, ordered by azimuth. Update 1 uses the
first 4 in that order for every strategy (one side of the object, the case where the next choice
matters most). Updates 2 and 3 then take 4 more views each, chosen
- sequentially: the next 4 in azimuth order (the supplementary's sequential trajectory);
- at random: 4 of the remaining, seeded per object and draw; random is a distribution, so each
  object's random score is the mean over several draws (one draw alone varies by about as much as
  the strategies differ);
- guided: greedily by next-view guidance on the current reconstruction (viewing quality on its mesh,
  weighted by the model's uncertainty), restricted to the remaining pool views, as a photographer
  would be told; once no view adds anything, the rest as far as possible from every view so far.
After each update the output views are scored exactly as `lirm eval` scores them. Guided is then
compared with each other strategy object by object: the mean difference with its 95% interval
(evaluation/paired_difference.py), and whether that says guided wins, loses or is within noise.

Any progressive reconstructor can be studied: LIRM, or the carved visual hull
(evaluation/carved_hull.py), whose quality comes only from the pixels it is given.
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
from lirm.engine.evaluation.paired_difference import PairedDifference, paired_difference

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
    random_draws: int = 5  # seeded random choices per object; its score is their mean
    graded: bool = True  # guided views by viewing quality (next_views.greedy_views); False: binary 60° coverage
    seed: int = 0
    eval: EvalConfig = field(default_factory=EvalConfig)


def azimuth_order(obj: HeldoutObject) -> list[int]:
    """The object's input views sorted by azimuth, then elevation: the sequential sweep."""
    pool = sorted({i for s in obj.protocol.input_sets for i in s})
    angles = {i: camera_angles(obj.views.cameras[i]) for i in pool}
    return sorted(pool, key=lambda i: (round(angles[i][0], 3), angles[i][1]))


def guided_choice(gl, fields: list, obj: HeldoutObject, used: list[int], remaining: list[int], k: int,
                  resolution: int = 48, uncertainty: bool = True, graded: bool = True) -> list[int]:
    mesh, _ = field_surface(fields[-1], resolution, face_budget=3000)  # no surface yet: the bounding sphere
    weights = (guidance_weights(vertex_uncertainty(fields, mesh.vertices, mesh.vertex_normals)["total"])
               if uncertainty else None)
    coverage = SurfaceCoverage(gl, mesh.vertices, mesh.faces, mesh.vertex_normals)
    try:
        cameras = obj.views.cameras
        chosen, _, _ = greedy_views(coverage, [cameras[i] for i in used], [cameras[i] for i in remaining], k, weights,
                                    graded=graded)
    finally:
        coverage.release()
    # Nothing left to gain (all of the surface covered): the rest spread out, as far as possible from
    # every view so far, instead of bunching next to them.
    spread = farthest_views([cameras[i] for i in used], [cameras[i] for i in remaining], k - len(chosen), tuple(chosen))
    return [remaining[i] for i in chosen + spread]


def choose_views(strategy: str, gl, fields: list, obj: HeldoutObject, used: list[int], remaining: list[int], k: int,
                 rng: np.random.Generator, resolution: int = 48, uncertainty: bool = True, graded: bool = True) -> list[int]:
    if strategy == "sequential":
        return remaining[:k]
    if strategy == "random":
        return [remaining[i] for i in sorted(rng.choice(len(remaining), size=min(k, len(remaining)), replace=False))]
    if strategy == "guided":
        return guided_choice(gl, fields, obj, used, remaining, k, resolution, uncertainty, graded)
    raise ValueError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}")


def true_surface_coverage(gl, obj: HeldoutObject, samples: int = 4000) -> SurfaceCoverage | None:
    """Coverage of the object's true surface (area-uniform samples), to say what each trajectory saw."""
    if obj.mesh is None:
        return None
    vertices, faces = obj.mesh
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    points, face_index = trimesh.sample.sample_surface(mesh, samples, seed=0)
    return SurfaceCoverage(gl, vertices, faces, mesh.vertex_normals, points=points, point_normals=mesh.face_normals[face_index])


METRICS = ("psnr", "ssim", "albedo", "roughness", "metallic", "chamfer", "coverage")
LOWER_IS_BETTER = {"chamfer"}


@dataclass
class TrajectoryResult:
    scores: EvalResult  # the paper's metrics after each update (mean over objects, and over draws for random)
    coverage: list[float]  # mean share of the true surface seen well by the inputs so far, after each update
    # per_object[metric][update - 1][object]: the object's score (its draws' mean for random)
    per_object: dict[str, list[list[float | None]]] = field(default_factory=dict)
    # per_draw[metric][update - 1][object][draw]: every run (one draw for guided and sequential)
    per_draw: dict[str, list[list[list[float | None]]]] = field(default_factory=dict)


def _run_scores(s: dict[str, list[float]]) -> dict[str, float | None]:
    """One run's scores after one update: means over its output views (Chamfer and coverage as they are)."""
    out = {}
    for metric in METRICS:
        values = [v for v in s.get(metric, []) if v is not None and np.isfinite(v)]
        out[metric] = float(np.mean(values)) if values else (float("inf") if metric == "chamfer" and s.get(metric) else None)
    return out


def _trajectory(model, strategy: str, gl, obj: HeldoutObject, truth: SurfaceCoverage | None, config: TrajectoryConfig,
                rng: np.random.Generator, device, per_update: dict[int, dict[str, list[float]]]) -> list[dict[str, float | None]]:
    """One object through `config.updates` updates with views chosen by `strategy`: the run's scores
    after each update (and its output views' scores appended to `per_update`, as `lirm eval` pools them)."""
    order = azimuth_order(obj)
    outputs = obj.protocol.outputs[:config.eval.output_views] if config.eval.output_views else obj.protocol.outputs
    used = order[:config.views_per_update]
    state = model.initial_state(1)
    fields: list = []
    runs = []
    for update in range(1, config.updates + 1):
        if update > 1:
            remaining = [i for i in order if i not in used]
            batch = choose_views(strategy, gl, fields[-2:], obj, used, remaining, config.views_per_update, rng,
                                 config.mesh_resolution, config.uncertainty, config.graded)
            used = used + batch
        else:
            batch = used
        if not batch:
            break
        state = model.update(state, model_inputs(model, obj, batch, device))
        fields.append(model.decode(state))
        s: dict[str, list[float]] = {}
        score_field(fields[-1], obj, outputs, config.eval, s)
        if truth is not None:
            seen = truth.covered([obj.views.cameras[i] for i in used]) > 0
            s["coverage"] = [float(seen.mean())]
        for metric, values in s.items():
            per_update[update].setdefault(metric, []).extend(values)
        runs.append(_run_scores(s))
    return runs


@torch.no_grad()
def run_trajectory_study(model, objects: list[HeldoutObject], gl, config: TrajectoryConfig = TrajectoryConfig(),
                         strategies: tuple[str, ...] = STRATEGIES,
                         progress: Callable[[str, int, int], None] | None = None) -> dict[str, TrajectoryResult]:
    """Per strategy, the paper's metrics after each update (mean over objects' output views), the
    true-surface coverage of the views chosen so far, and every object's own scores."""
    if config.random_draws < 1:
        raise ValueError(f"random_draws must be at least 1, got {config.random_draws}")
    device = model_device(model)
    draws = {s: config.random_draws if s == "random" else 1 for s in strategies}
    total, done = sum(draws.values()) * len(objects), 0
    truths = [true_surface_coverage(gl, obj) for obj in objects]
    results = {}
    try:
        for strategy in strategies:
            per_update: dict[int, dict[str, list[float]]] = {u: {} for u in range(1, config.updates + 1)}
            per_draw = {m: [[[] for _ in objects] for _ in range(config.updates)] for m in METRICS}
            for o_index, (obj, truth) in enumerate(zip(objects, truths)):
                for draw in range(draws[strategy]):
                    if progress:
                        progress(f"{strategy}: {obj.name}", done, total)
                    # Draw 0 is the seed the study always used; the others follow from it.
                    rng = np.random.default_rng([config.seed, o_index] + ([draw] if draw else []))
                    runs = _trajectory(model, strategy, gl, obj, truth, config, rng, device, per_update)
                    for u, run in enumerate(runs):
                        for metric in METRICS:
                            per_draw[metric][u][o_index].append(run[metric])
                    done += 1
            per_object = {m: [[_mean_or_none(d) for d in by_object] for by_object in by_update] for m, by_update in per_draw.items()}
            scores = EvalResult("synthetic", [o.name for o in objects], [update_scores(u, s) for u, s in per_update.items() if s],
                                "LPIPS not computed in this study")
            coverage = [float(np.mean(s["coverage"])) if s.get("coverage") else float("nan") for s in per_update.values() if s]
            results[strategy] = TrajectoryResult(scores, coverage, per_object, per_draw)
    finally:
        for truth in truths:
            if truth is not None:
                truth.release()
    return results


def _mean_or_none(values: list[float | None]) -> float | None:
    finite = [v for v in values if v is not None and np.isfinite(v)]
    if finite:
        return float(np.mean(finite))
    return float("inf") if values and any(v is not None for v in values) else None


def guided_margin(results: dict[str, TrajectoryResult], against: str = "random") -> list[dict]:
    """Guided minus `against`, per update and metric (positive = guided better; CD: against - guided):
    the mean over objects under the metric's name, and `intervals[metric]`, the paired difference with
    its 95% interval and verdict (None where a metric has no scores)."""
    guided, other = results["guided"], results[against]
    rows = []
    for u, row in enumerate(guided.scores.rows):
        intervals: dict[str, PairedDifference | None] = {
            metric: paired_difference(guided.per_object[metric][u], other.per_object[metric][u], metric in LOWER_IS_BETTER)
            for metric in METRICS}
        entry: dict = {"update": row.update, "intervals": intervals}
        for metric, d in intervals.items():
            entry[metric] = None if d is None else d.mean
        rows.append(entry)
    return rows


def random_spread(result: TrajectoryResult, metric: str = "psnr") -> list[float | None]:
    """Per update, the mean over objects of the standard deviation of `metric` across random draws:
    how much one draw alone can be off."""
    out = []
    for by_object in result.per_draw[metric]:
        sds = [float(np.std([v for v in d if v is not None], ddof=1)) for d in by_object if sum(v is not None for v in d) > 1]
        out.append(float(np.mean(sds)) if sds else None)
    return out


def share_of_draws_beaten(guided: TrajectoryResult, random: TrajectoryResult, metric: str = "psnr") -> list[float | None]:
    """Per update, the share of random draws (over all objects) that guided's run scores above."""
    out = []
    for g_by_object, r_by_object in zip(guided.per_draw[metric], random.per_draw[metric]):
        wins = [float(g[0] > r) for g, rs in zip(g_by_object, r_by_object) if g and g[0] is not None
                for r in rs if r is not None]
        out.append(float(np.mean(wins)) if wins else None)
    return out


def quality_follows_coverage(result: TrajectoryResult, metric: str = "psnr") -> list[float | None]:
    """Per update, how much a strategy's scores follow the coverage of the views it drew: the
    correlation of `metric` with true-surface coverage across its draws, within objects (each
    object's draws centred on their own means, then pooled). About 0: the reconstructor's quality
    does not depend on which views it got, so no choice of views can beat another beyond noise;
    positive: more coverage, better scores. Needs several draws (random)."""
    out = []
    for scores_by_object, coverage_by_object in zip(result.per_draw[metric], result.per_draw["coverage"]):
        q, c = [], []
        for scores, coverage in zip(scores_by_object, coverage_by_object):
            pairs = np.array([(s, v) for s, v in zip(scores, coverage) if s is not None and v is not None and np.isfinite(s)])
            if len(pairs) > 1:
                q.append(pairs[:, 0] - pairs[:, 0].mean())
                c.append(pairs[:, 1] - pairs[:, 1].mean())
        if not q:
            out.append(None)
            continue
        q_all, c_all = np.concatenate(q), np.concatenate(c)
        out.append(float(np.corrcoef(q_all, c_all)[0, 1]) if q_all.std() > 0 and c_all.std() > 0 else None)
    return out
