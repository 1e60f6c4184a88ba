"""The paper's evaluation after each progressive update: novel-view PSNR, SSIM and LPIPS (AlexNet,
when its weights were fetched: `lirm fetch lpips`), albedo PSNR with Stanford-ORB's per-channel
scale, roughness and metallic PSNR on the object's pixels, and the Chamfer distance of the
marching-cubes mesh to the true surface.

The same state is updated with input set 1, 2, 3, 4 in turn; after each update every output view
is volume-rendered and scored. Numbers are means over output views (images) or objects (Chamfer).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import Callable, Protocol

import numpy as np
import torch

from lirm.engine.export.field_mesh import field_sdf_grid
from lirm.engine.export.marching_cubes import marching_cubes
from lirm.engine.export.silhouette_offset import surface_level
from lirm.engine.metrics import psnr, scaled_albedo_psnr, ssim
from lirm.engine.model.field import device_of
from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.model.volume_renderer import VolumeRenderConfig, fitted_render, render_camera
from lirm.engine.synth.view_crops import crop_like_capture, resize_views
from lirm.engine.perceptual.lpips_network import LPIPS, load_lpips
from lirm.engine.perceptual.lpips_weights import missing_weights_reason

from .chamfer import chamfer_distance, surface_samples
from .heldout_sets import HeldoutObject

Progress = Callable[[str, int, int], None]
METRIC_NETWORK = "alex"  # LPIPS' own default for evaluation (VGG is the training loss's)


class ProgressiveReconstructor(Protocol):
    """What the evaluation drives: LIRM, or a baseline of evaluation/baselines.py."""

    config: object  # has `image_size`, the side of the input views

    def initial_state(self, batch: int = 1): ...

    def update(self, state, views): ...

    def decode(self, state): ...


@dataclass(frozen=True)
class EvalConfig:
    updates: int = 4
    render: VolumeRenderConfig = field(default_factory=lambda: VolumeRenderConfig(samples_per_ray=96, numerical_normals=False))
    occupancy: OccupancyConfig = field(default_factory=lambda: OccupancyConfig(resolution=96))
    mesh_resolution: int = 96
    chamfer_points: int = 20_000
    output_views: int | None = None  # at most this many output views per object (None: the protocol's 12)


@dataclass
class UpdateScores:
    update: int
    psnr: float
    ssim: float
    lpips: float | None
    albedo_psnr: float | None
    roughness_psnr: float | None
    metallic_psnr: float | None
    chamfer: float | None
    views: int
    seconds: float | None = None  # mean time per object to reconstruct up to this row (scoring excluded)
    relight_psnr_h: float | None = None  # the relighting test (relighting.py): HDR PSNR under a new environment
    relight_psnr_l: float | None = None  # ... and on the tone-mapped display image
    relight_ssim: float | None = None
    relight_lpips: float | None = None

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class EvalResult:
    set_name: str
    objects: list[str]
    rows: list[UpdateScores]
    lpips_note: str  # why LPIPS is absent, or "" when it was computed
    lighting: dict[str, str] = field(default_factory=dict)  # object -> "lit by X; relit by Y" (the relighting test)

    def to_dict(self) -> dict:
        return {"set": self.set_name, "objects": self.objects, "lpips": self.lpips_note or "computed",
                "lighting": self.lighting, "rows": [r.to_dict() for r in self.rows]}


def lighting_of(objects: list[HeldoutObject]) -> dict[str, str]:
    """What lit each object's views, and what relights it (or why nothing does)."""
    out = {}
    for o in objects:
        relit = (f"relit by {o.relight.name} (rotated {o.relight.rotation_deg:.0f}°)" if o.relight is not None
                 else "not relit (no second environment)")
        out[o.name] = f"lit by {o.lit_by or 'the photos’ own light'}; {relit}"
    return out


def _finite_mean(values: list[float]) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(finite)) if finite else None


def _field_mesh_points(field, config: EvalConfig) -> np.ndarray:
    values, origin, spacing = field_sdf_grid(field, config.mesh_resolution, narrow_band_stride=4)
    # The surface the export takes (a refined field's at its silhouettes' level: silhouette_offset.py).
    level = surface_level(field)
    mesh = marching_cubes(values - level if level else values, origin, spacing)
    return surface_samples(mesh.vertices, mesh.faces, config.chamfer_points, seed=0)


def model_device(model) -> torch.device:
    if isinstance(model, torch.nn.Module):
        model.eval()
        return next(model.parameters()).device
    return torch.device("cpu")


def model_inputs(model, obj: HeldoutObject, indices, device):
    """The views at `indices` as the model takes them: cut like capture crops, at its input size."""
    chosen = obj.views.select(indices)
    size = model.config.image_size
    inputs = resize_views(chosen, size) if obj.inputs_prepared else crop_like_capture(chosen, size)
    return inputs.view_batch(device=device)


@torch.no_grad()
def score_field(field_, obj: HeldoutObject, outputs: list[int], config: EvalConfig, scores: dict[str, list[float]],
                lpips_net=None, relighter=None, photos=None, lighting=None) -> None:
    """Render the field from the output views and append each metric to `scores` (the Chamfer distance
    once); with a `relighter` (relighting.Relighter), also the relighting test of its export (its
    textures fitted to `photos` under `lighting` when both are given: Relighter.score)."""
    device = device_of(field_)
    render, grid = fitted_render(field_, config.render, config.occupancy)
    for i in outputs:
        out = render_camera(field_, obj.views.cameras[i], render, grid, device=device)
        truth = obj.views
        coverage = truth.mask[i]
        inside = coverage > 0.99
        colour = np.clip(out["colour"], 0.0, 1.0)
        scores.setdefault("psnr", []).append(psnr(colour, truth.image[i]))
        scores.setdefault("ssim", []).append(ssim(colour, truth.image[i]))
        if lpips_net is not None:
            scores.setdefault("lpips", []).append(lpips_net.image_distance(colour, truth.image[i]))
        if inside.any() and truth.albedo is not None:
            denom = np.maximum(coverage, 1e-6)
            scores.setdefault("albedo", []).append(scaled_albedo_psnr(out["albedo"], truth.albedo[i] / denom[..., None], inside))
            scores.setdefault("roughness", []).append(psnr(out["roughness"], truth.roughness[i] / denom, inside))
            scores.setdefault("metallic", []).append(psnr(out["metallic"], truth.metallic[i] / denom, inside))
    if obj.surface is not None and len(obj.surface):
        scores.setdefault("chamfer", []).append(chamfer_distance(_field_mesh_points(field_, config), obj.surface))
    if relighter is not None:
        relighter.score(field_, obj, outputs, scores, lpips_net, photos, lighting)


def update_scores(update: int, s: dict[str, list[float]]) -> UpdateScores:
    return UpdateScores(update, _finite_mean(s.get("psnr", [])) or float("nan"), _finite_mean(s.get("ssim", [])) or float("nan"),
                        _finite_mean(s.get("lpips", [])), _finite_mean(s.get("albedo", [])), _finite_mean(s.get("roughness", [])),
                        _finite_mean(s.get("metallic", [])), _mean_or_inf(s.get("chamfer")), len(s.get("psnr", [])),
                        _finite_mean(s.get("seconds", [])), _finite_mean(s.get("relight_psnr_h", [])),
                        _finite_mean(s.get("relight_psnr_l", [])), _finite_mean(s.get("relight_ssim", [])),
                        _finite_mean(s.get("relight_lpips", [])))


def metric_lpips(device="cpu") -> tuple[LPIPS | None, str]:
    """The LPIPS metric's network, or None and the note saying why it is skipped."""
    why = missing_weights_reason(METRIC_NETWORK)
    return (None, f"LPIPS skipped: {why}") if why else (load_lpips(METRIC_NETWORK).to(device), "")


@torch.no_grad()
def evaluate_heldout(model: ProgressiveReconstructor, objects: list[HeldoutObject], config: EvalConfig = EvalConfig(),
                     set_name: str = "synthetic", progress: Progress | None = None,
                     cancel: Callable[[], bool] | None = None, relighter=None) -> EvalResult:
    device = model_device(model)
    per_update: dict[int, dict[str, list[float]]] = {u: {} for u in range(1, config.updates + 1)}
    lpips_net, lpips_note = metric_lpips(device)
    for k, obj in enumerate(objects):
        if progress:
            progress(f"evaluating {obj.name}", k, len(objects))
        outputs = obj.protocol.outputs[:config.output_views] if config.output_views else obj.protocol.outputs
        state = model.initial_state(1)
        seconds = 0.0
        for u, input_set in enumerate(obj.protocol.input_sets[:config.updates], start=1):
            if cancel is not None and cancel():
                raise KeyboardInterrupt("evaluation cancelled")
            inputs = model_inputs(model, obj, input_set, device)
            start = time.perf_counter()
            state = model.update(state, inputs)
            decoded = model.decode(state)
            seconds += time.perf_counter() - start
            per_update[u].setdefault("seconds", []).append(seconds)
            score_field(decoded, obj, outputs, config, per_update[u], lpips_net, relighter)
    rows = [update_scores(u, s) for u, s in per_update.items() if s]
    return EvalResult(set_name, [o.name for o in objects], rows, lpips_note, lighting_of(objects))


def _mean_or_inf(values: list[float] | None) -> float | None:
    if not values:
        return None
    return float(np.mean(values))  # inf when some update produced no surface at all: shown as such
