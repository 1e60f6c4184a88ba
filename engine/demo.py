"""`lirm demo`: the main job on built-in data only (nothing to download).

1. An overview sheet of the built-in objects under the built-in environments (the renderer).
2. A synthetic photo shoot: a built-in object on a gravel floor under the built-in sky, photographed
   from 16 orbit views and saved as JPEG photos, with the true cameras and masks kept aside.
3. The whole capture pipeline on those photos as if a user had taken them (COLMAP posing,
   normalisation, automatic masks, crops), and its pose and mask accuracy against the truth.
4. Progressive LIRM updates on that capture with the shipped weights (untrained ones when none ship,
   said loudly), then a per-scene refinement on all its views (engine/refine/: the shipped prior alone
   gives a blob), and the asset exported as `asset.glb` (a validated, textured PBR glTF).
5. `relit.png`: the asset beside the original object under two built-in environments the photos were
   not taken in, from four sides.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from lirm.renderer.context import create_headless_context
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS, make_procedural_environment

from .assets.asset_source import resolve_asset
from .io.atomic_files import atomic_write_bytes, atomic_write_json
from .lighting.capture_lighting import write_hdr
from .io.images import to_uint8, write_png
from .orbit_render import OrbitRenderConfig, normalizing_transform, orbit_for
from .synth.capture_scene import SyntheticCaptureConfig, render_synthetic_capture
from .synth.procedural_objects import BUILTIN_OBJECTS

TRUE_LIGHTING_FILE = "lighting.hdr"  # in truth/


@dataclass
class DemoConfig:
    overview_size: int = 256
    environment_width: int = 1024
    shoot: SyntheticCaptureConfig = field(default_factory=SyntheticCaptureConfig)
    shoot_environment: str = "sky"
    relight_environments: tuple[str, ...] = ("studio", "overcast")  # not the shoot's: relighting, not replay
    capture_only: bool = False  # stop after the capture (the app's demo capture; it reconstructs on its own)
    preset: str | None = None  # the model preset; None: the shipped checkpoint's (untrained small when none ships)
    export_grid: int = 128
    export_faces: int = 20_000
    export_texture: int = 512
    refine_minutes: float | None = 3.0  # per-scene refinement before the export (None: export the LIRM state as is)
    # Inverse-render the materials under the shoot's estimated lighting (`lirm refine --materials`):
    # the demo relights its asset, and a plain radiance fit bakes the sky's shading into the albedo
    # (the label side, in shadow in the photos, came out dark and barely readable; README).
    refine_materials: bool = True
    # The built-in mug stated as a real one (a typical mug's height), so that the demo's exports are
    # in metres with the base on y = 0, as a user's are after `lirm capture --real-size`.
    real_height_m: float | None = 0.095


@dataclass
class DemoResult:
    out_dir: Path
    overview: Path
    photos: Path
    capture: Path
    accuracy: dict
    asset: Path | None = None
    weights: str = ""
    trained: bool = False
    relit: Path | None = None
    relit_rows: list[str] = field(default_factory=list)
    relit_test: object | None = None  # the relighting test of the asset against the original (DemoRelightResult)


def run_demo(out_dir: str | Path, config: DemoConfig = DemoConfig(), progress: Callable[[str], None] | None = None) -> DemoResult:
    out_dir = Path(out_dir)
    say = progress or (lambda message: None)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        environments = {name: make_procedural_environment(name, width=config.environment_width) for name in PROCEDURAL_ENVIRONMENTS}
        say(f"rendering the overview of {len(BUILTIN_OBJECTS)} objects x {len(environments)} environments")
        overview = _overview(renderer, environments, config, out_dir / "overview.png")
        say(f"photographing the '{config.shoot.object_name}' from {config.shoot.views} views under '{config.shoot_environment}'")
        shoot = render_synthetic_capture(renderer, environments[config.shoot_environment], config.shoot)
    finally:
        renderer.release()
        ctx.release()
    photos = out_dir / "photos"
    truth = out_dir / "truth"
    for frame_id, image in shoot.images.items():
        ok, jpeg = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 95])
        atomic_write_bytes(photos / f"shot_{frame_id}.jpg", jpeg.tobytes())
        write_png(truth / "masks" / f"shot_{frame_id}.png", shoot.masks[frame_id])
    # What lit the object: the shoot's environment with the lit ground below (capture_scene.py).
    write_hdr(truth / TRUE_LIGHTING_FILE, shoot.lit_by)
    atomic_write_json(truth / "transforms.json", {
        "camera_model": "OPENCV",
        "environment": config.shoot_environment,
        "environment_width": config.environment_width,
        "lighting_file": TRUE_LIGHTING_FILE,  # what lit the object: `lirm bench lighting` compares with it
        "object": config.shoot.object_name,  # what was photographed: `lirm bench relight` relights it
        "object_seed": config.shoot.seed,
        "frames": [{"file_path": f"../photos/shot_{k}.jpg", **cam.to_dict()} for k, cam in sorted(shoot.cameras.items())],
    })

    say("running the capture pipeline on the photos (posing with COLMAP, masks, crops)")
    from .capture.pipeline import run_capture

    capture_dir = out_dir / "capture"
    summary = run_capture(photos, capture_dir, progress=lambda stage, done, total: None)
    accuracy = capture_accuracy(summary.capture, shoot.cameras, {f"shot_{k}": m for k, m in shoot.masks.items()})
    accuracy["registered"] = f"{summary.registered}/{len(shoot.images)}"
    if config.capture_only:
        return DemoResult(out_dir, overview, photos, capture_dir, accuracy)
    asset, source = _reconstruct_and_export(capture_dir, out_dir / "asset.glb", config, say)
    say(f"relighting the asset beside the original under {' and '.join(config.relight_environments)}")
    relit, rows = _relight(asset, out_dir / "relit.png", config)
    from .bench.demo_relight_bench import run_demo_relight_bench

    say("scoring the relit asset against the original (the relighting test, `lirm bench relight`)")
    scored = run_demo_relight_bench(out_dir, asset, config.relight_environments)
    return DemoResult(out_dir, overview, photos, capture_dir, accuracy, asset, source.description, source.trained, relit, rows,
                      scored)


def _relight(asset: Path, path: Path, config: DemoConfig) -> tuple[Path, list[str]]:
    from .assets.model_loader import load_model as load_asset
    from .relight_sheet import relit_sheet

    original = resolve_asset(config.shoot.object_name, seed=config.shoot.seed)
    environments = {name: make_procedural_environment(name, width=config.environment_width // 2)
                    for name in config.relight_environments}
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        return relit_sheet(renderer, [(f"original {config.shoot.object_name}", original), ("exported asset", load_asset(asset))],
                           environments, path)
    finally:
        renderer.release()
        ctx.release()


def _reconstruct_and_export(capture_dir: Path, asset_path: Path, config: DemoConfig, say: Callable[[str], None]):
    from dataclasses import replace

    from .export.capture_export import export_capture
    from .export.export_asset import ExportConfig
    from .export.field_mesh import MeshExtractionConfig
    from .model.pretrained import load_model
    from .reconstruction.session import ReconstructConfig, run_reconstruction

    source = load_model(None, config.preset)
    say(f"reconstructing with LIRM ({source.description}{'' if source.trained else ', UNTRAINED'})")
    if source.note:
        say(f"about these weights: {source.note}")
    pictures = replace(ReconstructConfig(), novel_views=2, render_size=96)
    run_reconstruction(capture_dir, source, pictures)
    if config.refine_minutes:
        from .reconstruction.refine_step import run_refine
        from .refine.config import refine_preset

        what = " with the materials under the photos' lighting" if config.refine_materials else ""
        minutes = f"{config.refine_minutes:g} minute{'' if config.refine_minutes == 1 else 's'}"
        say(f"refining the reconstruction on all the views for {minutes}{what}")
        refine = refine_preset("default", minutes=config.refine_minutes, inverse_rendering=config.refine_materials)
        refined = run_refine(capture_dir, source, refine, render=pictures)
        say(f"refinement: {refined.steps} steps in {refined.seconds:.0f} s from {refined.started_from}")
        for note in refined.notes:  # whether the material network was heard, and why (its familiarity check)
            if "material network" in note:
                say(note)
    if config.real_height_m:
        from .capture.real_size import set_real_size

        set_real_size(capture_dir, "height", config.real_height_m, "lirm demo")
    say("exporting the asset (surface, UV atlas, baked PBR textures, .glb and .usdz)")
    export = ExportConfig(mesh=replace(MeshExtractionConfig(), resolution=config.export_grid, face_budget=config.export_faces),
                          texture_size=config.export_texture, usdz=True)
    result, _ = export_capture(capture_dir, asset_path, export, source=source)
    if result.texture_fit is not None:
        say(result.texture_fit.summary())
    return result.path, source


def capture_accuracy(capture, true_cameras: dict, true_masks_by_name: dict) -> dict:
    """Pose errors after a similarity alignment, and mask IoU, matched by the photos' file names."""
    from .capture.alignment import pose_errors
    from .capture.undistort import undistort_image
    from lirm.engine.cameras import Camera

    by_name = {state.record.original.stem: fid for fid, state in capture.frames.items()}
    truth_ids = {f"shot_{k}": k for k in true_cameras}
    estimated, reference = {}, {}
    for name, fid in by_name.items():
        if fid in capture.cameras and name in truth_ids:
            estimated[name] = capture.cameras[fid]
            reference[name] = true_cameras[truth_ids[name]]
    result = dict(pose_errors(estimated, reference)) if len(estimated) >= 3 else {}
    source_cameras = capture.settings.get("source_cameras", {})
    ious = {}
    for name, fid in by_name.items():
        mask = capture.read_mask(fid) if fid in capture.cameras else None
        if mask is None or name not in true_masks_by_name:
            continue
        truth = true_masks_by_name[name]
        if capture.frames[fid].pinhole_image is not None and fid in source_cameras:
            truth, _ = undistort_image(truth, Camera.from_dict(source_cameras[fid]))  # compare in the same pixels
        if truth.shape != mask.shape:
            truth = cv2.resize(truth, mask.shape[::-1], interpolation=cv2.INTER_NEAREST)
        a, b = mask > 127, truth > 127
        ious[name] = float((a & b).sum() / max((a | b).sum(), 1))
    if ious:
        result["mask_iou_mean"] = float(np.mean(list(ious.values())))
        result["mask_iou_min"] = float(np.min(list(ious.values())))
    return result


def _overview(renderer: PBRRenderer, environments: dict, config: DemoConfig, path: Path) -> Path:
    """One three-quarter view per object (rows) and environment (columns)."""
    s = config.overview_size
    camera = orbit_for(OrbitRenderConfig(views=1, width=s, height=s, start_azimuth_deg=-35.0))[0]
    sheet = np.zeros((s * len(BUILTIN_OBJECTS), s * len(environments), 3), np.uint8)
    lightings = [renderer.prepare_lighting(env) for env in environments.values()]
    try:
        for row, name in enumerate(BUILTIN_OBJECTS):
            model = resolve_asset(name)
            scene = renderer.upload(model.meshes, normalizing_transform(model.bounds))
            try:
                for col, lighting in enumerate(lightings):
                    out = renderer.render_view(scene, camera, lighting, RenderSettings(supersample=2))
                    sheet[row * s:(row + 1) * s, col * s:(col + 1) * s] = to_uint8(out.beauty)
            finally:
                scene.release()
    finally:
        for lighting in lightings:
            lighting.maps.release()
    return write_png(path, sheet)
