"""`lirm refine CAPTURE`: per-scene refinement as one more step of the capture's reconstruction history.

The refined field is fitted to the capture's prepared views (engine/refine/) and saved as a step
like an update's: reconstruction/update_NN/state.safetensors (a refined field, model/field_state.py)
with the same novel-view pictures, a refine.json (what it started from, the settings, the time, the
losses, the hold-out scores), an entry in capture.json's `updates` with `"kind": "refine"`, and a
record in summary.json. Export, guidance, evaluation and the app read it exactly like an update's.

Where it starts (`init`):
- "auto" (default): the last refined step if the history has one (a warm start: after new photos
  and a new update, refining goes on from the earlier refinement with all the views), else the
  latest LIRM update or, when a hull agrees better with the photos, that hull's shape with the
  update's materials ("hull-lirm": the hull of the voxels' centres, or of their footprints where
  that one is closer, as for parts thinner than a voxel), else the carved hull;
- "lirm": the latest LIRM update's decoded field; "hull": the visual hull of the masks; "hull-lirm": the
  hull's shape with the latest update's roughness and metallic; "scratch".

The step is written into a hidden folder first and moved into place only when it is complete, so a
cancelled or killed refinement leaves the history as it was.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.capture_lock import capture_lock
from lirm.engine.capture.history_journal import HistoryBuild
from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_json
from lirm.engine.metrics import psnr, ssim
from lirm.engine.model.field_state import load_field, save_field_state
from lirm.engine.model.pretrained import ModelSource
from lirm.engine.model.volume_renderer import fitted_render, render_camera
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig
from lirm.engine.refine.refinable_field import RefinableField
from lirm.engine.refine.refine_views import RefineViews
from lirm.engine.refine.refiner import RefineTick, refine_field

from .novel_views import novel_view_cameras
from .session import ReconstructConfig, last_update_entry, open_checked, prepared_views, summary_with, write_pictures

INIT_CHOICES = ("auto", "lirm", "hull", "hull-lirm", "scratch")


@dataclass
class RefineStepResult:
    number: int  # the step's place in the history
    out_dir: Path
    started_from: str
    steps: int
    seconds: float
    stopped: str
    holdout: dict | None  # {"views": [...], "psnr": x, "ssim": y} when views were held out
    notes: list[str]


def warm_start_schedule(config: RefineConfig) -> RefineConfig:
    """Going on from a refined field: its finest planes and sharpest 1/beta from the first step (the
    coarse-to-fine start would first blur away the detail already fitted)."""
    return replace(config, plane_resolutions=(config.plane_resolutions[-1],), inv_beta=(config.inv_beta[1], config.inv_beta[1]))


def holdout_split(frames: list[str], every: int | None) -> tuple[list[str], list[str]]:
    """(fitted, held out): every `every`-th view (the 1st, (K+1)-th, ...) is kept out of the fit."""
    if not every:
        return frames, []
    if every < 2:
        raise LirmUserError(f"--holdout-every must be at least 2 (every K-th view held out), got {every}")
    held = frames[every - 1::every]
    fitted = [f for f in frames if f not in held]
    if not held or not fitted:
        raise LirmUserError(f"--holdout-every {every} leaves nothing to {'hold out' if not held else 'fit'} "
                            f"among {len(frames)} views; choose a smaller K")
    return fitted, held


def _starting_field(capture: Capture, init: str, source: ModelSource, views: RefineViews, hull, footprint_hull, grid,
                    config: RefineConfig, notes: list[str], cancel) -> tuple:
    """The refinable field to start from and a sentence naming it. `hull`, `footprint_hull`: the views'
    masks carved by each voxel's centre and by its footprint; `grid`: the sampling bounds."""
    model = source.model
    resolution = config.plane_resolutions[0]
    refined = [(i, e) for i, e in enumerate(capture.updates, start=1) if e.get("kind") == "refine"]
    if init == "auto" and refined:
        number, entry = refined[-1]
        field = load_field(capture.root / entry["state"], model)
        return RefinableField.from_field(field), f"refinement {number} (warm start)"

    def hull_start(materials=None, shape=None):
        return initial_fields.from_hull(hull if shape is None else shape, model.config, model.heads, resolution, config.hull_init_steps, config.seed,
                                        cancel, materials=materials)

    if init in ("auto", "lirm", "hull-lirm"):
        base = last_update_entry(capture.updates)
        if base is not None:
            field = load_field(capture.root / base["state"], model)
            named = f"LIRM update {base['update']}"
            if init == "hull-lirm":
                return hull_start(field), f"carved hull with {named}'s materials"
            from_lirm = initial_fields.from_lirm(field, resolution)
            if init == "lirm":
                return from_lirm, named
            # Whichever of LIRM and the hull agrees better with the views; the hull takes the prior's
            # roughness and metallic (it has none of its own; README: what that was worth).
            # The footprint hull (the sampling bounds) is a third candidate only where it kept parts the
            # centres' hull lost: elsewhere it is that hull a voxel fatter, and its regression costs 5-9 s.
            third = (hull_start(field, footprint_hull) if initial_fields.footprint_keeps_lost_parts(hull, footprint_hull)
                     else None)
            start, chosen, losses = initial_fields.closer_start(from_lirm, hull_start(field), views, grid, config, third)
            if chosen == "lirm":
                return start, named
            which = "carved hull" if chosen == "hull-lirm" else "hull carved by the voxels' footprints (thin parts kept)"
            notes.append(f"the {which} agrees better with the photos than {named} "
                         f"(loss {losses[chosen]:.4f} against {losses['lirm']:.4f}): starting from the hull's shape "
                         f"with the update's materials")
            return start, f"carved hull with {named}'s materials"
        if init != "auto":
            wanted = "start from" if init == "lirm" else "take materials from"
            raise LirmUserError(f"{capture.root} has no LIRM update to {wanted}: run `lirm reconstruct {capture.root}` "
                                f"first, or refine with --init hull")
        notes.append("no LIRM update yet: starting from the carved hull of the masks")
        init = "hull"
    if init == "hull":
        return hull_start(), "carved hull"
    return initial_fields.scratch(model.config, resolution, config.seed), "scratch"


def run_refine(capture_dir: str | Path, source: ModelSource, config: RefineConfig = RefineConfig(), init: str = "auto",
               holdout_every: int | None = None, render: ReconstructConfig = ReconstructConfig(),
               progress: Callable[[RefineTick], None] | None = None,
               cancel: Callable[[], bool] | None = None, live_path: Path | None = None,
               live_every: float = 5.0) -> RefineStepResult:
    """`live_path`: where to keep the field as it is while it fits (a refined-state file, replaced every
    `live_every` seconds and removed at the end), for a viewer to show. The capture is locked while
    it runs; the refined step joins the history only when it is finished (a killed or failed run
    leaves the capture as it was)."""
    if init not in INIT_CHOICES:
        raise LirmUserError(f"--init must be one of {', '.join(INIT_CHOICES)}, got {init!r}")
    with capture_lock(capture_dir, "lirm refine"):
        return _refine_locked(capture_dir, source, config, init, holdout_every, render, progress, cancel, live_path, live_every)


def _refine_locked(capture_dir, source: ModelSource, config: RefineConfig, init: str, holdout_every: int | None,
                   render: ReconstructConfig, progress, cancel, live_path: Path | None, live_every: float) -> RefineStepResult:
    capture = open_checked(capture_dir)
    views_by_frame = prepared_views(capture)
    fitted, held = holdout_split(list(views_by_frame), holdout_every)
    views = RefineViews.from_prepared([views_by_frame[f] for f in fitted])
    notes: list[str] = []
    radius = source.model.config.radius
    hulls = initial_fields.views_hulls(views, config, radius)
    hull, footprint_hull = hulls.centres, hulls.footprint
    notes.extend(hulls.sentences())
    grid = initial_fields.views_sampling_grid(views, config, radius, hulls)
    if grid is None:
        notes.append("the masks' visual hull is empty (masks or poses disagree): sampling the whole bounding sphere")
    refinable, started_from = _starting_field(capture, init, source, views, hull, footprint_hull, grid, config, notes, cancel)
    if started_from.endswith("(warm start)"):
        config = warm_start_schedule(config)
    live = None
    if live_path is not None:
        def live(current) -> None:
            save_field_state(current.frozen_field(), live_path, updates=len(capture.updates) + 1, extra={"live": True})
    lighting = None
    if config.inverse_rendering:
        from lirm.engine.lighting.capture_lighting import load_capture_lighting, missing_lighting_reason
        from lirm.engine.lighting.panorama_lighting import PanoramaLighting

        estimate = load_capture_lighting(capture.root)
        if estimate is None:
            notes.append(f"no lighting estimate in the capture ({missing_lighting_reason(capture.root)}): the "
                         "materials are not inverse-rendered")
        else:
            lighting = PanoramaLighting.from_capture_lighting(estimate, config.lighting_height, config.lighting_sharpest_lobe,
                                                                    config.light_lobes, config.lighting_smooth_scale)
    try:
        result = refine_field(refinable, views, config, grid, progress, cancel, live, live_every, lighting=lighting,
                              start_has_materials=started_from not in ("carved hull", "scratch"))
    finally:
        if live_path is not None:
            Path(live_path).unlink(missing_ok=True)
    field = result.field.frozen_field()
    if result.material_network:
        notes.append(result.material_network)

    number = len(capture.updates) + 1
    with HistoryBuild(capture) as build:
        folder = build.folder(number)
        save_field_state(field, folder / "state.safetensors", updates=number, extra={"started_from": started_from})
        holdout = _holdout_scores(field, [views_by_frame[f] for f in held], render) if held else None
        start = time.perf_counter()
        cameras = novel_view_cameras(list(capture.cameras.values()), render.novel_views, render.render_size)
        occupied, skipped = write_pictures(field, cameras, render, folder, torch.device("cpu"))
        render_seconds = time.perf_counter() - start
        record = {"update": number, "kind": "refine", "frames": fitted, "held_out": held, "started_from": started_from,
                  "init": init, "seconds": round(result.seconds, 2), "steps": result.steps, "stopped": result.stopped,
                  "best_step": result.best_step, "best_loss": result.best_loss, "holdout": holdout,
                  "settings": config.to_dict(), "losses": result.history, "notes": notes,
                  "material_network": result.material_network}
        atomic_write_json(folder / "refine.json", record)
        if result.lighting is not None:
            _save_fitted_lighting(result.lighting, folder)
        state_path = build.final_state_path(number)
        rel = str(Path(state_path).parent)
        entry = {"update": number, "kind": "refine", "frames": fitted, "held_out": held,
                 "started_from": started_from, "seconds": round(result.seconds, 2), "steps": result.steps,
                 "weights": source.description, "trained": source.trained, "state": state_path}
        if lighting is not None:  # the export's texture fit compares through the same tone curve
            entry["camera_response"] = lighting.camera_response
        log = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "action": "refine", "update": number,
               "started_from": started_from, "seconds": round(result.seconds, 2), "steps": result.steps,
               "stopped": result.stopped}
        summary = summary_with(capture.root / "reconstruction", source, render, number - 1, [
            {"update": number, "kind": "refine", "frames": fitted, "seconds": round(result.seconds, 2),
             "render_seconds": round(render_seconds, 2), "occupied_fraction": occupied, "skipped_samples": skipped,
             "out_dir": rel, "started_from": started_from, "holdout": holdout}])
        build.commit(number - 1, [entry], summary, [log])
    out_dir = capture.root / rel
    return RefineStepResult(number, out_dir, started_from, result.steps, result.seconds, result.stopped, holdout, notes)


def _save_fitted_lighting(lighting, folder: Path) -> None:
    """The lighting fitted with the materials, beside the state (lighting.hdr and a picture)."""
    import cv2

    from lirm.engine.io.images import write_png
    from lirm.engine.lighting.capture_lighting import write_hdr
    from lirm.renderer.tonemap import tonemap

    environment = lighting.environment()
    write_hdr(folder / "lighting.hdr", environment)
    key = max(float(np.median(environment.radiance.mean(-1))), 1e-6)
    picture = cv2.resize(tonemap(environment.radiance * (0.18 / key)).astype(np.float32), (512, 256), interpolation=cv2.INTER_NEAREST)
    write_png(folder / "lighting.png", (picture * 255).astype(np.uint8))


@torch.no_grad()
def _holdout_scores(field, held: list, render: ReconstructConfig) -> dict:
    """PSNR and SSIM of the refined field rendered from the held-out views' own crops, over white."""
    config, grid = fitted_render(field, replace(render.render, numerical_normals=False), render.occupancy)
    psnrs, ssims = [], []
    for view in held:
        out = render_camera(field, view.camera, config, grid)
        colour = np.clip(out["colour"], 0.0, 1.0)
        psnrs.append(psnr(colour, view.image_masked))
        ssims.append(ssim(colour, view.image_masked))
    return {"views": [v.frame_id for v in held], "psnr": float(np.mean(psnrs)), "ssim": float(np.mean(ssims)),
            "per_view_psnr": [round(float(p), 2) for p in psnrs]}
