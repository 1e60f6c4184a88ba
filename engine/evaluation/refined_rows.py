"""Refinement in the evaluation (`lirm eval --refine`, `lirm bench refine`): after the updates, the
field is refined on the same input views the updates saw and scored on the same output views, so
its rows sit beside the model's and the baselines'.

- "refined from LIRM": the model's state after the last scored update, decoded and refined;
- "refined from the hull": the carved visual hull of the same views' masks, refined.

The input views are cut as a capture cuts photos, at the protocol's own size (the refinement fits
the crops at their full prepared size, as `lirm refine` does); a real capture's are its prepared crops.
Seconds count everything from the views to the refined field (the updates too), not the scoring.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig
from lirm.engine.refine.refine_views import RefineViews
from lirm.engine.refine.refiner import refine_field

from .evaluate import EvalConfig, EvalResult, lighting_of, metric_lpips, model_device, model_inputs, score_field, update_scores
from .heldout_sets import HeldoutObject

# What a held-out object's inverse rendering shades with: the capture-style estimate from the inputs'
# backgrounds (what a user has), or an oracle knowing the environment that really lit the inputs, as
# the renderer's own tables ("truth") or area-averaged into the fit's own panorama ("truth-panorama").
LIGHTING_SOURCES = ("estimate", "truth", "truth-panorama")

Progress = Callable[[str, int, int], None]


def refine_inputs(obj: HeldoutObject, indices: list[int]) -> RefineViews:
    """The input views at `indices` as the refinement fits them: at their own pixels. A held-out
    object's views are whole frames at the protocol's size, each pixel the mean over its own footprint
    (as a photo's is, and as the texture fit's footprint models it); cropped round the object and
    resized back to that size, as the network's inputs are, they were upsampled 1.25-1.85 x by
    interpolation: blurred, each view by its own amount at its own offsets, and the fit's detail with
    them (README, "The refinement at the inputs' own pixels": +1.4 dB of relighting on the synthetic
    set, a wash on the glTF set). A capture's prepared views are taken as they are."""
    return RefineViews.from_object_views(obj.views.select(indices), [f"view_{i:02d}" for i in indices])


@torch.no_grad()
def lirm_field(model, obj: HeldoutObject, updates: int):
    """The model's decoded field after the object's first `updates` input sets."""
    device = model_device(model)
    state = model.initial_state(1)
    for input_set in obj.protocol.input_sets[:updates]:
        state = model.update(state, model_inputs(model, obj, input_set, device))
    return model.decode(state)


@dataclass
class RefinedObject:
    field: object  # the refined field, frozen
    seconds: float
    steps: int
    views: RefineViews  # the input views it was fitted to
    lighting: object | None  # the lighting fitted with the materials (None without them)
    start: str = ""  # where the fit started: the init asked for, or the one "auto" chose
    material_network: str = ""  # whether the fit heard the material network, and why (RefineResult's)


def refine_object(model, obj: HeldoutObject, updates: int, refine: RefineConfig, init: str, true_lighting=None,
                  lighting_source: str = "estimate") -> RefinedObject:
    """One held-out object refined. `lighting_source` (LIGHTING_SOURCES): what the inverse rendering
    shades with; "truth" needs `true_lighting`, a PBRRenderer whose tables it reads."""
    sets = obj.protocol.input_sets[:updates]
    views = refine_inputs(obj, [i for s in sets for i in s])
    start = time.perf_counter()
    hulls = initial_fields.views_hulls(views, refine, model.config.radius)
    hull, footprint_hull = hulls.centres, hulls.footprint
    grid = initial_fields.views_sampling_grid(views, refine, model.config.radius, hulls)
    resolution = refine.plane_resolutions[0]
    chosen = init
    if init == "lirm":
        refinable = initial_fields.from_lirm(lirm_field(model, obj, updates), resolution)
    elif init == "auto":  # as `lirm refine` starts a capture with no refinement yet
        prediction = lirm_field(model, obj, updates)
        def from_hull(shape):
            return initial_fields.from_hull(shape, model.config, model.heads, resolution, refine.hull_init_steps,
                                            refine.seed, materials=prediction)
        # The footprint hull a candidate only where it kept parts the centres' hull lost (as `lirm refine`).
        from_footprint_hull = (from_hull(footprint_hull) if initial_fields.footprint_keeps_lost_parts(hull, footprint_hull)
                               else None)
        refinable, chosen, _ = initial_fields.closer_start(initial_fields.from_lirm(prediction, resolution), from_hull(hull),
                                                           views, grid, refine, from_footprint_hull)
    elif init in ("hull", "hull-lirm"):
        materials = lirm_field(model, obj, updates) if init == "hull-lirm" else None
        refinable = initial_fields.from_hull(hull, model.config, model.heads, resolution, refine.hull_init_steps, refine.seed,
                                             materials=materials)
    elif init == "scratch":
        refinable = initial_fields.scratch(model.config, resolution, refine.seed)
    else:
        raise ValueError(f"unknown init {init!r}")
    lighting = None
    if refine.inverse_rendering:
        if lighting_source == "truth":
            if true_lighting is None:
                raise ValueError("the oracle lighting reads the renderer's tables: pass its PBRRenderer as true_lighting")
            lighting = oracle_lighting(obj, true_lighting)
        elif lighting_source == "truth-panorama":
            lighting = true_panorama_lighting(obj, refine)
        elif lighting_source == "estimate":
            lighting = input_lighting(obj, [i for s in sets for i in s], refine)
        else:
            raise ValueError(f"unknown lighting source {lighting_source!r}; choose one of: {', '.join(LIGHTING_SOURCES)}")
    result = refine_field(refinable, views, refine, grid, lighting=lighting, start_has_materials=chosen in ("lirm", "hull-lirm", "hull-lirm-footprint"))
    return RefinedObject(result.field.frozen_field(), time.perf_counter() - start, result.steps, views, result.lighting, chosen,
                         result.material_network)


def input_lighting(obj: HeldoutObject, indices: list[int], refine: RefineConfig):
    """The lighting estimate a capture would make, from the input views' backgrounds (the full frames
    with the environment behind), as the fittable panorama the inverse rendering starts from. The
    held-out sets' backdrops are environments at infinity, so the proxy sphere is far away."""
    from lirm.engine.lighting.capture_lighting import CaptureLightingConfig, estimate_capture_lighting
    from lirm.engine.lighting.panorama_lighting import PanoramaLighting

    chosen = obj.views.select(indices)
    images = {i: np.round(chosen.image_bg[k] * 255).astype(np.uint8) for k, i in enumerate(indices)}
    masks = {i: np.where(chosen.mask[k] > 0.5, 255, 0).astype(np.uint8) for k, i in enumerate(indices)}
    cameras = {i: chosen.cameras[k] for k, i in enumerate(indices)}
    estimate = estimate_capture_lighting(images, masks, cameras, CaptureLightingConfig(proxy_radius=50.0))
    return PanoramaLighting.from_capture_lighting(estimate, refine.lighting_height, refine.lighting_sharpest_lobe,
                                                  refine.light_lobes, refine.lighting_smooth_scale)


def _input_light(obj: HeldoutObject) -> tuple:
    """(environment, rotation_deg, exposure_ev) that lit the inputs: what every oracle starts from."""
    if obj.input_light is None:
        raise ValueError(f"{obj.name}: the light of its inputs is unknown (a real capture): no oracle lighting")
    return obj.input_light


def true_environment_in_world(obj: HeldoutObject):
    """The environment that lit the inputs as the scene's world sees it: turned by its rotation and
    scaled by its exposure, as the renderer applies them (an Environment in the world frame)."""
    from lirm.renderer.environment import Environment, rotation_about_z

    environment, rotation_deg, exposure_ev = _input_light(obj)
    directions, _ = environment.texel_directions()
    local = directions.reshape(-1, 3) @ rotation_about_z(-rotation_deg).T  # world -> environment frame
    radiance = environment.lookup(local).reshape(environment.radiance.shape) * 2.0 ** exposure_ev
    return Environment(radiance.astype(np.float32), name=f"{environment.name} (world frame)")


def true_panorama_lighting(obj: HeldoutObject, refine: RefineConfig):
    """The oracle in the fit's own terms: the true environment area-averaged into the fitted
    panorama's texels (no compact lights) and held fixed. Against `oracle_lighting` it says what the
    panorama costs as a representation; against the estimate, what the estimate's content costs."""
    from lirm.engine.lighting.panorama_lighting import PanoramaLighting

    panorama = PanoramaLighting.from_environment(true_environment_in_world(obj), refine.lighting_height,
                                                 refine.lighting_sharpest_lobe, 0, refine.lighting_smooth_scale)
    return panorama.requires_grad_(False)


def oracle_lighting(obj: HeldoutObject, renderer):
    """The environment that really lit the inputs, as the renderer's own tables, held fixed."""
    from lirm.engine.lighting.fixed_lighting import FixedLighting
    from lirm.engine.lighting.lighting_tables import tables_from_lighting

    environment, rotation_deg, exposure_ev = _input_light(obj)
    lighting = renderer.prepare_lighting(environment, rotation_deg=rotation_deg, intensity_ev=exposure_ev)
    try:
        return FixedLighting(tables_from_lighting(renderer, lighting))
    finally:
        lighting.maps.release()


def evaluate_refined(model, objects: list[HeldoutObject], config: EvalConfig, refine: RefineConfig, init: str,
                     set_name: str = "synthetic", progress: Progress | None = None, relighter=None) -> EvalResult:
    scores: dict[str, list[float]] = {}
    lpips_net, lpips_note = metric_lpips()
    for k, obj in enumerate(objects):
        if progress:
            progress(f"refining {obj.name}", k, len(objects))
        refined = refine_object(model, obj, config.updates, refine, init)
        outputs = obj.protocol.outputs[:config.output_views] if config.output_views else obj.protocol.outputs
        scores.setdefault("seconds", []).append(refined.seconds)
        with torch.no_grad():
            score_field(refined.field, obj, outputs, config, scores, lpips_net, relighter=relighter, photos=refined.views,
                        lighting=refined.lighting)
    if progress:
        progress("refined", len(objects), len(objects))
    updates = min(config.updates, min(len(o.protocol.input_sets) for o in objects)) if objects else config.updates
    return EvalResult(set_name, [o.name for o in objects], [update_scores(updates, scores)], lpips_note, lighting_of(objects))


RELIGHT_KEYS = ("relight_psnr_h", "relight_psnr_l")
MATERIAL_KEYS = ("roughness_psnr", "metallic_psnr") + RELIGHT_KEYS


def per_object_scores(model, objects: list[HeldoutObject], config: EvalConfig, refine: RefineConfig, init: str,
                      relighter=None, lighting_source: str = "estimate") -> list[dict]:
    """One dict per object (for studies that pair objects across settings); with a `relighter`, the
    material and relighting scores too; `lighting_source` other than "estimate" (LIGHTING_SOURCES):
    an oracle that knows the inputs' environment ("truth" reads the relighter's renderer's tables)."""
    rows = []
    lpips_net, _ = metric_lpips()
    for obj in objects:
        oracle = relighter.renderer if lighting_source == "truth" and relighter is not None else None
        refined = refine_object(model, obj, config.updates, refine, init, oracle, lighting_source)
        outputs = obj.protocol.outputs[:config.output_views] if config.output_views else obj.protocol.outputs
        scores: dict[str, list[float]] = {}
        with torch.no_grad():
            score_field(refined.field, obj, outputs, config, scores, lpips_net, relighter=relighter, photos=refined.views,
                        lighting=refined.lighting)
        row = update_scores(config.updates, scores).to_dict()
        keys = ("psnr", "ssim", "lpips", "albedo_psnr", "roughness_psnr", "metallic_psnr", "chamfer") + (
            RELIGHT_KEYS + ("relight_lpips",) if relighter is not None else ())
        baked = {k: float(np.mean(v)) for k, v in scores.items() if k.startswith(("baked_", "variant_", "fit_", "swap_", "exported_"))}  # RelightConfig's extras
        rows.append({"object": obj.name, "start": refined.start, "material_network": refined.material_network,
                     "seconds": refined.seconds, "steps": refined.steps,
                     **{k: row[k] for k in keys}, **baked})
    return rows


def mean_of(rows: list[dict], key: str) -> float:
    values = [r[key] for r in rows if r.get(key) is not None and np.isfinite(r[key])]
    return float(np.mean(values)) if values else float("nan")
