"""The relighting test (Stanford-ORB's, issue 19): a reconstruction is exported as a user gets it (the
.glb: mesh, UV atlas, baked PBR textures), loaded back, rendered through the project's renderer
under an environment that lit none of its inputs, and compared with the true object under it.

- PSNR-H: linear HDR radiance on the object's pixels, with the truth's brightest object pixel as
  the peak. The pixels are Stanford-ORB's: the true mask shrunk by a margin (5 x 5 at 512 px, scaled
  to the view: 3 x 3 at 128 px), so that the test weighs light and materials, not where the
  silhouette's edge falls by a pixel; a missing part still costs (it renders black there), an extra
  one does not.
- PSNR-L: the same after the set's exposure, ACES and sRGB (the display image), peak 1. (Stanford-ORB
  tone-maps with sRGB alone; ours is what the viewport shows. Its MSE also sums the three channels
  per pixel, which puts its figures 4.8 dB below an ordinary PSNR's; ours is the ordinary one.)
- SSIM and LPIPS (AlexNet; skipped, with why, where its weights were never fetched) on the display
  images, the background black in both.
As Stanford-ORB does, the prediction is first scaled per channel by least squares on those pixels:
albedo and light are only known up to a common scale, which no method can recover.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from lirm.engine.metrics import ssim
from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.tonemap import tonemap


@dataclass
class RelightTruth:
    """The true object under the relighting environment, seen from the output views."""

    environment: Environment
    rotation_deg: float
    exposure_ev: float
    radiance: dict[int, np.ndarray]  # output view -> (H, W, 3) linear HDR, black background
    mask: dict[int, np.ndarray]  # output view -> (H, W) coverage
    # For the swap study (relight_swaps.py) only: output view -> the truth's G-buffer at RELIGHT_SUPERSAMPLE
    # times the view's size.
    gbuffers: dict | None = None

    @property
    def name(self) -> str:
        return self.environment.name


RELIGHT_SUPERSAMPLE = 2  # the relighting's own supersampling: the swap study shades G-buffers this much finer
RELIGHT_SETTINGS = RenderSettings(show_environment=False, supersample=RELIGHT_SUPERSAMPLE)


def render_relight_truth(renderer: PBRRenderer, meshes, transform: np.ndarray, cameras, outputs: list[int],
                         environment: Environment, rotation_deg: float, exposure_ev: float,
                         keep_gbuffers: bool = False) -> RelightTruth:
    """`keep_gbuffers`: also keep the truth's G-buffers for the swap study (a few MB a view)."""
    scene = renderer.upload(meshes, transform)
    lighting = renderer.prepare_lighting(environment, rotation_deg=rotation_deg)
    radiance, mask, gbuffers = {}, {}, {} if keep_gbuffers else None
    try:
        for i in outputs:
            out = renderer.render_view(scene, cameras[i], lighting, RELIGHT_SETTINGS)
            radiance[i], mask[i] = out.radiance, out.mask
            if keep_gbuffers:
                gbuffers[i] = _gbuffer(renderer.render_view(scene, cameras[i].scaled(RELIGHT_SUPERSAMPLE), lighting,
                                                            RenderSettings(show_environment=False, supersample=1)))
    finally:
        scene.release()
        lighting.maps.release()
    return RelightTruth(environment, rotation_deg, exposure_ev, radiance, mask, gbuffers)


def _gbuffer(out):
    """What the swap study reads of a render: no radiance, display image or depth."""
    from types import SimpleNamespace

    return SimpleNamespace(albedo=out.albedo, roughness=out.roughness, metallic=out.metallic, normal=out.normal, mask=out.mask)


PICTURE_VIEWS = 3  # output views shown per picture


@dataclass(frozen=True)
class RelightConfig:
    grid: int = 96  # marching-cubes samples per side for the exported mesh
    faces: int = 8_000
    texture: int = 256
    # Where a row brings its input photos and fitted lighting (the refined rows with materials), the
    # export fits its textures to them, as `lirm export` does for a capture refined with materials.
    fit_textures: bool = True
    # With the fit on: also score the export with the baked textures, under "baked_" keys (a paired
    # ablation of the fit on the same refined field: `lirm bench refine --materials --texture-fit both`).
    also_baked: bool = False
    # With the fit on: also score the export fitted with these settings instead (a TextureFitConfig),
    # under "variant_" keys: a paired ablation of a texture-fit setting on the same refined field
    # (`lirm bench refine --materials --texture-fit variant --fit-option KEY=VALUE`).
    variant_fit: object | None = None
    # Also score the swap study (relight_swaps.py) on the scored export, under "swap_" keys: needs the
    # truth's G-buffers (heldout sets built with relight_gbuffers).
    swap_study: bool = False


class Relighter:
    """Scores fields by the relighting test; owns one GL context for the exports and the renders.

    With `pictures`, each scored export also leaves a picture there (relight_pictures.py): the truth
    and the relit export side by side on the first output views, under the relighting environment
    and, where the object has one (`relight_also`), a second one; named after `row` (set by the
    caller per contender) and the object; a row scored after several updates keeps the last."""

    def __init__(self, config: RelightConfig = RelightConfig(), pictures: Path | None = None):
        from lirm.renderer.context import create_headless_context

        self.config = config
        self.pictures = Path(pictures) if pictures else None
        self.row = "row"
        self.ctx = create_headless_context()
        self.renderer = PBRRenderer(self.ctx)
        self._lighting_key = None
        self._lighting = None

    def score(self, field_, obj, outputs: list[int], scores: dict[str, list[float]], lpips_net=None,
              photos=None, lighting=None) -> None:
        """`photos` (PhotoViews: the row's input views) and `lighting` (fitted with its materials): the
        export's textures are fitted to them (config.fit_textures)."""
        truth = getattr(obj, "relight", None)
        if truth is None:
            return
        from lirm.engine.assets.model_loader import load_model
        from lirm.engine.export.export_asset import ExportConfig, export_field
        from lirm.engine.export.photo_texture_fit import TextureFitConfig
        from lirm.engine.export.field_mesh import MeshExtractionConfig, NoSurfaceError

        mesh = MeshExtractionConfig(resolution=self.config.grid, face_budget=self.config.faces)
        fitting = self.config.fit_textures and photos is not None and lighting is not None
        config = ExportConfig(mesh=mesh, texture_size=self.config.texture, texture_fit=TextureFitConfig() if fitting else None)
        with tempfile.TemporaryDirectory(prefix="lirm-relight-") as tmp:
            path = Path(tmp) / "asset.glb"
            try:
                exported = export_field(field_, path, config, context=self.ctx, photos=photos, lighting=lighting)
            except NoSurfaceError:
                for key in ("relight_psnr_h", "relight_psnr_l", "relight_ssim"):
                    scores.setdefault(key, []).append(float("nan"))
                return
            model = load_model(path)  # what a user opens: the .glb read back, in its own (the field's) frame
            if fitting:  # the fit's own time, to weigh a variant's against
                scores.setdefault("fit_seconds", []).append(exported.seconds.get("texture_fit", float("nan")))
            extra = [("baked_", None)] if fitting and self.config.also_baked else []
            if fitting and self.config.variant_fit is not None:
                extra.append(("variant_", self.config.variant_fit))
            for prefix, fit in extra:
                other = Path(tmp) / f"{prefix}asset.glb"
                result = export_field(field_, other, replace(config, texture_fit=fit), context=self.ctx, photos=photos,
                                      lighting=lighting)
                if fit is not None:
                    scores.setdefault(prefix + "fit_seconds", []).append(result.seconds.get("texture_fit", float("nan")))
                other_scene = self.renderer.upload(load_model(other).meshes)
                try:
                    self._score_scene(other_scene, obj, truth, outputs, scores, lpips_net, prefix=prefix)
                finally:
                    other_scene.release()
        scene = self.renderer.upload(model.meshes)
        try:
            shown = self._score_scene(scene, obj, truth, outputs, scores, lpips_net,
                                      keep=PICTURE_VIEWS if self.pictures is not None else 0)
            if self.config.swap_study:
                self._score_swaps(scene, obj, truth, outputs, scores)
            panels = [(truth.name, truth.exposure_ev, shown)]
            also = getattr(obj, "relight_also", None)
            if shown and also is not None:  # the pictures' second environment (not scored)
                second = self._lighting_for(obj, also)
                views = [i for i in outputs if i in also.radiance][:PICTURE_VIEWS]
                panels.append((also.name, also.exposure_ev, [
                    (also.radiance[i], also.mask[i], self.renderer.render_view(
                        scene, obj.views.cameras[i], second, RELIGHT_SETTINGS).radiance)
                    for i in views]))
        finally:
            scene.release()
        if shown:
            from .relight_pictures import write_relight_picture

            write_relight_picture(self.pictures / f"{_slug(self.row)}__{_slug(obj.name)}.png", panels,
                                  f"{self.row} / {obj.name}")

    def _score_scene(self, scene, obj, truth: RelightTruth, outputs: list[int], scores: dict[str, list[float]], lpips_net,
                     prefix: str = "", keep: int = 0) -> list:
        """The relighting metrics of an uploaded export on the output views, appended under
        `prefix`-ed keys; returns the first `keep` views' (truth, mask, render) for the pictures."""
        lighting = self._lighting_for(obj, truth)
        shown = []
        for i in outputs:
            out = self.renderer.render_view(scene, obj.views.cameras[i], lighting, RELIGHT_SETTINGS)
            for key, value in relight_metrics(out.radiance, out.mask, truth.radiance[i], truth.mask[i], truth.exposure_ev,
                                              lpips_net).items():
                scores.setdefault(prefix + key, []).append(value)
            if len(shown) < keep:
                shown.append((truth.radiance[i], truth.mask[i], out.radiance))
        return shown

    def _score_swaps(self, scene, obj, truth: RelightTruth, outputs: list[int], scores: dict[str, list[float]]) -> None:
        from lirm.engine.lighting.lighting_tables import tables_from_lighting

        from .relight_swaps import exported_material_scores, swapped_images

        if truth.gbuffers is None:
            raise ValueError("the swap study needs the truth's G-buffers: build the held-out set with relight_gbuffers")
        lighting = self._lighting_for(obj, truth)
        tables = tables_from_lighting(self.renderer, lighting)
        for i in outputs:
            camera = obj.views.cameras[i].scaled(RELIGHT_SUPERSAMPLE)
            export = self.renderer.render_view(scene, camera, lighting, RenderSettings(show_environment=False, supersample=1))
            _, directions = camera.pixel_rays()
            for name, (radiance, coverage) in swapped_images(export, truth.gbuffers[i], tables, directions,
                                                             RELIGHT_SUPERSAMPLE).items():
                metrics = relight_metrics(radiance, coverage, truth.radiance[i], truth.mask[i], truth.exposure_ev)
                if not metrics:  # no scored pixel in this view (as in _score_scene: the view adds nothing)
                    continue
                for key in ("relight_psnr_h", "relight_psnr_l"):
                    scores.setdefault(f"swap_{name}_{key}", []).append(metrics[key])
            for key, value in exported_material_scores(export, truth.gbuffers[i]).items():
                scores.setdefault(key, []).append(value)

    def _lighting_for(self, obj, truth: RelightTruth):
        key = (obj.name, truth.name, truth.rotation_deg)
        if key != self._lighting_key:
            if self._lighting is not None:
                self._lighting.maps.release()
            self._lighting = self.renderer.prepare_lighting(truth.environment, rotation_deg=truth.rotation_deg)
            self._lighting_key = key
        return self._lighting

    def release(self) -> None:
        if self._lighting is not None:
            self._lighting.maps.release()
        self.renderer.release()
        self.ctx.release()


def scored_pixels(true_mask: np.ndarray) -> np.ndarray:
    """The true mask shrunk by Stanford-ORB's margin (2 px at 512 px), scaled to the view, at least 1 px."""
    margin = max(1, int(round(2 * true_mask.shape[0] / 512)))
    inside = (np.asarray(true_mask) > 0.5).astype(np.uint8)
    return cv2.erode(inside, np.ones((2 * margin + 1, 2 * margin + 1), np.uint8), borderValue=0) > 0


def relight_metrics(radiance: np.ndarray, mask: np.ndarray, true_radiance: np.ndarray, true_mask: np.ndarray,
                    exposure_ev: float, lpips_net=None) -> dict[str, float]:
    region = scored_pixels(true_mask)
    if not region.any():
        return {}
    p = scale_to_truth(radiance, true_radiance, region)
    t = np.asarray(true_radiance, np.float64)
    peak = max(float(t[region].max()), 1e-6)
    mse_h = float(((p[region] - t[region]) ** 2).mean())
    shown_p, shown_t = tonemap(p, exposure_ev), tonemap(t, exposure_ev)
    mse_l = float(((shown_p[region] - shown_t[region]) ** 2).mean())
    out = {"relight_psnr_h": _db(peak * peak, mse_h), "relight_psnr_l": _db(1.0, mse_l), "relight_ssim": ssim(shown_p, shown_t)}
    if lpips_net is not None:
        out["relight_lpips"] = lpips_net.image_distance(shown_p, shown_t)
    return out


def scale_to_truth(radiance: np.ndarray, true_radiance: np.ndarray, region: np.ndarray) -> np.ndarray:
    """The prediction scaled per channel by least squares on `region` (Stanford-ORB's scale invariance)."""
    p = np.asarray(radiance, np.float64)
    t = np.asarray(true_radiance, np.float64)
    scale = (p[region] * t[region]).sum(0) / np.maximum((p[region] ** 2).sum(0), 1e-12)
    return p * scale


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text).strip("_") or "x"


def _db(peak_squared: float, mse: float) -> float:
    return float("inf") if mse == 0 else float(10.0 * math.log10(peak_squared / mse))
