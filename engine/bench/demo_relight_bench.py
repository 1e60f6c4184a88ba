"""`lirm bench relight DEMO_OUT`: the demo shoot's exported asset relit beside the original object,
scored by the relighting test (relighting.py: per-channel scale, PSNR-H, PSNR-L, SSIM) under
environments that lit none of the photos.

The held-out sets score fields fitted to cut-outs; this scores what a user of a real capture gets:
the whole path from photos (COLMAP's poses, automatic masks, the lighting read from the
backgrounds, exposures and white balance matched) to the .glb. The export is placed in the shoot's
frame by the similarity that takes the capture's camera centres (moved into the file's frame by the
export's recorded placement) onto the shoot's true ones; how well that worked is reported too (the
silhouette IoU of the placed asset against the shoot's true masks), since a misplaced asset would
score its placement, not its materials.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lirm.engine.errors import LirmUserError

RELIGHT_ELEVATIONS_DEG = (10.0, 40.0)  # two rings: below and above the shoot's one ring at 30 degrees
RELIGHT_AZIMUTH_OFFSET_DEG = 11.25  # half the shoot's spacing: views between the photos'
ALIGNMENT_SCALE = 0.25  # the shoot's cameras at a quarter of their size for the placement check


@dataclass
class DemoRelightResult:
    asset: Path
    object_name: str
    alignment_iou: float  # mean over the shoot's views: the placed asset's silhouette against the true mask
    views: int
    scores: dict[str, dict[str, float]] = field(default_factory=dict)  # environment -> metric -> mean over views
    picture: Path | None = None

    def mean(self, key: str) -> float:
        """A metric's mean over the environments."""
        return float(np.mean([s[key] for s in self.scores.values()]))

    def report(self) -> str:
        lines = [f"{self.asset} relit beside the original {self.object_name} ({self.views} views per environment, "
                 f"none of them the photos'):",
                 f"  placement in the shoot's frame: silhouette IoU {self.alignment_iou:.3f} against the true masks"]
        for name, s in self.scores.items():
            lines.append(f"  under {name}: PSNR-L {s['relight_psnr_l']:.2f} dB, PSNR-H {s['relight_psnr_h']:.2f} dB, "
                         f"SSIM {s['relight_ssim']:.3f}")
        if len(self.scores) > 1:
            lines.append(f"  mean: PSNR-L {self.mean('relight_psnr_l'):.2f} dB, PSNR-H {self.mean('relight_psnr_h'):.2f} dB")
        if self.picture is not None:
            lines.append(f"  picture (truth above, asset below): {self.picture}")
        return "\n".join(lines)


def shoot_object(truth_file: dict) -> tuple[str, int]:
    """The object the demo photographed and its seed (older outputs do not say: the demo's defaults)."""
    from lirm.engine.synth.capture_scene import SyntheticCaptureConfig

    default = SyntheticCaptureConfig()
    return str(truth_file.get("object", default.object_name)), int(truth_file.get("object_seed", default.seed))


def placement_in_shoot(demo_out: Path, asset: Path, truth_file: dict) -> np.ndarray:
    """The 4x4 similarity taking the exported file's frame to the shoot's."""
    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.export.glb_placement import read_placement

    from .shoot_frame import shoot_similarity

    placement = read_placement(asset)
    if placement is None:
        raise LirmUserError(f"{asset}: it does not say where it was placed (not a `lirm export` .glb); "
                            f"export the demo's capture with `lirm export {demo_out / 'capture'} -o ASSET.glb`")
    scale, rotation, translation = shoot_similarity(Capture.open(demo_out / "capture"), truth_file, moved_by=placement)
    matrix = np.eye(4)
    matrix[:3, :3] = scale * rotation
    matrix[:3, 3] = translation
    return matrix


def relight_cameras(views: int, size: int):
    """Two rings round the unit sphere the shoot's object was scaled into, between the photos' azimuths."""
    from lirm.engine.orbit_render import OrbitRenderConfig, orbit_for

    per_ring = max(1, views // len(RELIGHT_ELEVATIONS_DEG))
    cameras = []
    for ring, elevation in enumerate(RELIGHT_ELEVATIONS_DEG):
        start = RELIGHT_AZIMUTH_OFFSET_DEG + ring * 180.0 / per_ring
        cameras += orbit_for(OrbitRenderConfig(views=per_ring, width=size, height=size, elevation_deg=elevation,
                                               start_azimuth_deg=start))
    return cameras


def run_demo_relight_bench(demo_out: str | Path, asset: str | Path | None = None,
                           environments: tuple[str, ...] | None = None, views: int = 8, size: int = 192,
                           picture: str | Path | None = None) -> DemoRelightResult:
    """`asset`: the export to score (default: the demo's asset.glb); `environments`: built-in names or
    .hdr/.exr files (default: the two the demo relights under)."""
    from lirm.engine.assets.asset_source import resolve_asset
    from lirm.engine.assets.environment_files import resolve_environment
    from lirm.engine.assets.model_loader import load_model
    from lirm.engine.demo import DemoConfig
    from lirm.engine.evaluation.relighting import RELIGHT_SETTINGS, relight_metrics, render_relight_truth
    from lirm.engine.evaluation.relight_pictures import write_relight_picture
    from lirm.engine.orbit_render import normalizing_transform
    from lirm.engine.synth.training_scenes import auto_exposure_ev
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    demo_out = Path(demo_out)
    asset = Path(asset) if asset else demo_out / "asset.glb"
    if not asset.is_file():
        raise LirmUserError(f"{asset}: no exported asset there; run `lirm demo -o {demo_out}` or "
                            f"`lirm export {demo_out / 'capture'} -o {asset}` first")
    demo = DemoConfig()
    truth_file = json.loads((demo_out / "truth" / "transforms.json").read_text())
    object_name, seed = shoot_object(truth_file)
    original = resolve_asset(object_name, seed=seed)
    exported = load_model(asset)
    placed = placement_in_shoot(demo_out, asset, truth_file)
    names = environments or demo.relight_environments
    lights = [resolve_environment(name, width=demo.environment_width // 2) for name in names]
    cameras = relight_cameras(views, size)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    result = DemoRelightResult(asset, object_name, float("nan"), len(cameras))
    panels = []
    try:
        scene = renderer.upload(exported.meshes, placed)
        try:
            result.alignment_iou = _placement_iou(renderer, scene, demo_out, truth_file)
            for environment in lights:
                exposure = auto_exposure_ev(environment)
                truth = render_relight_truth(renderer, original.meshes, normalizing_transform(original.bounds), cameras,
                                             list(range(len(cameras))), environment, 0.0, exposure)
                lighting = renderer.prepare_lighting(environment)
                scores: dict[str, list[float]] = {}
                shown = []
                try:
                    for i, camera in enumerate(cameras):
                        out = renderer.render_view(scene, camera, lighting, RELIGHT_SETTINGS)
                        for key, value in relight_metrics(out.radiance, out.mask, truth.radiance[i], truth.mask[i], exposure).items():
                            scores.setdefault(key, []).append(value)
                        if i % max(1, len(cameras) // 4) == 0 and len(shown) < 4:
                            shown.append((truth.radiance[i], truth.mask[i], out.radiance))
                finally:
                    lighting.maps.release()
                result.scores[environment.name] = {k: float(np.mean(v)) for k, v in scores.items()}
                panels.append((environment.name, exposure, shown))
        finally:
            scene.release()
    finally:
        renderer.release()
        ctx.release()
    if picture is not None:
        result.picture = write_relight_picture(Path(picture), panels, f"{asset.name} / original {object_name}")
    return result


def _placement_iou(renderer, scene, demo_out: Path, truth_file: dict) -> float:
    """The placed asset's silhouette against the shoot's true masks, from the shoot's own cameras."""
    from lirm.engine.cameras import Camera
    from lirm.engine.capture.masks import mask_iou
    from lirm.renderer.pbr_renderer import RenderSettings

    lighting = renderer.prepare_lighting(_grey_environment())
    ious = []
    try:
        for frame in truth_file["frames"]:
            mask_path = demo_out / "truth" / "masks" / f"{Path(frame['file_path']).stem}.png"
            if not mask_path.is_file():
                continue
            camera = Camera.from_dict(frame).scaled(ALIGNMENT_SCALE)
            out = renderer.render_view(scene, camera, lighting, RenderSettings(show_environment=False, supersample=1))
            true_mask = cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE).astype(np.float32)
            true_mask = cv2.resize(true_mask, (camera.width, camera.height), interpolation=cv2.INTER_AREA)
            ious.append(mask_iou(out.mask * 255.0, true_mask))
    finally:
        lighting.maps.release()
    return float(np.mean(ious)) if ious else float("nan")


def _grey_environment():
    from lirm.renderer.environment import Environment

    return Environment(np.full((8, 16, 3), 0.5, np.float32), name="grey")
