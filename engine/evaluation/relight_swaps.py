"""Where the relighting error comes from: the relit export with one part swapped for the truth's.

The export and the true object are each rasterised from an output view at the relighting's
supersampling (their G-buffers: albedo, roughness, metallic, shading normal, coverage), and shaded
again by the torch twin of the renderer (split_sum_shading.py, under the relighting environment's own
prefiltered tables) with parts exchanged between the two G-buffers pixel for pixel where both cover:

- `export`: nothing swapped (the twin's check: it equals the renderer's relit export);
- `truth_albedo` / `truth_materials`: the export's surface with the truth's albedo / albedo, roughness
  and metallic (what perfect materials on this geometry would score);
- `truth_roughness`: the export's albedo and metallic with the truth's roughness; `truth_albedo_roughness`
  / `truth_albedo_metallic`: the truth's albedo with its roughness / its metallic (the step from
  `truth_albedo` to `truth_materials` split between the two);
- `truth_geometry`: the truth's surface and normals with the export's albedo, roughness and metallic
  (what perfect geometry under these materials would score);
- `truth_albedo_detail`: the export's albedo with its detail (what a Gaussian of `DETAIL_SIGMA`
  output pixels removes) replaced by the truth's, its coarse colour and shading kept;
- `truth_albedo_coarse`: the other way round, the truth's coarse albedo with the export's detail.

Each is scored as the relighting test scores (relight_metrics: PSNR-L and PSNR-H on Stanford-ORB's
pixels, after the per-channel scale). A study, not a method: it reads the truth's materials.

Beside it, `exported_material_scores`: the export's own albedo, roughness and metallic against the
truth's in the same G-buffers (what a user gets, where the evaluation's material PSNRs score the
refined field's volume rendering, before the export's texture fit).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.metrics import psnr, scaled_albedo_psnr
from lirm.renderer.pbr_renderer import box_downsample

DETAIL_SIGMA = 2.0  # output pixels: what is finer than this Gaussian counts as the albedo's detail
EXPORTED_MATERIAL_KEYS = ("exported_albedo_psnr", "exported_roughness_psnr", "exported_metallic_psnr")
SWAPS = ("export", "truth_albedo", "truth_materials", "truth_geometry", "truth_albedo_detail", "truth_albedo_coarse",
         "truth_roughness", "truth_albedo_roughness", "truth_albedo_metallic")


def masked_blur(image: np.ndarray, coverage: np.ndarray, sigma: float) -> np.ndarray:
    """A Gaussian of `sigma` pixels over the covered pixels only (normalised), so that the background
    does not darken the edges."""
    weight = (coverage > 0.5).astype(np.float32)
    total = cv2.GaussianBlur(image * weight[..., None], (0, 0), sigma)
    return total / np.maximum(cv2.GaussianBlur(weight, (0, 0), sigma), 1e-6)[..., None]


def _shade_gbuffer(tables, albedo, roughness, metallic, normal, coverage, directions) -> np.ndarray:
    """(H, W, 3) radiance of a G-buffer under `tables`, black where not covered."""
    inside = coverage > 0.5
    as_tensor = lambda a: torch.from_numpy(np.ascontiguousarray(a[inside], dtype=np.float32))  # noqa: E731
    with torch.no_grad():
        radiance = shade(tables, as_tensor(albedo), as_tensor(roughness), as_tensor(metallic), as_tensor(normal),
                         -as_tensor(directions)).radiance.numpy()
    image = np.zeros(albedo.shape[:2] + (3,), np.float32)
    image[inside] = radiance
    return image


def swapped_images(export, truth, tables, directions: np.ndarray, supersample: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """(radiance, coverage) at the output resolution for every swap in SWAPS. `export` and `truth`:
    G-buffers (RenderOutput-like: albedo, roughness, metallic, normal, mask) at `supersample` times the
    output size; `directions`: the (H, W, 3) unit rays of their pixels."""
    both = (export.mask > 0.5) & (truth.mask > 0.5)

    def mix(base, donor):
        out = base.copy()
        out[both] = donor[both]
        return out

    sigma = DETAIL_SIGMA * supersample
    export_coarse = masked_blur(export.albedo, export.mask, sigma)
    truth_coarse = masked_blur(truth.albedo, truth.mask, sigma)
    # Detail as a ratio to the coarse colour, so that swapping it keeps the other's brightness there.
    truth_detail = np.clip(truth.albedo / np.maximum(truth_coarse, 1e-4), 0.0, 4.0)
    export_detail = np.clip(export.albedo / np.maximum(export_coarse, 1e-4), 0.0, 4.0)
    true_albedo, true_roughness, true_metallic = (mix(export.albedo, truth.albedo), mix(export.roughness, truth.roughness),
                                                  mix(export.metallic, truth.metallic))
    on_export = lambda albedo, roughness=export.roughness, metallic=export.metallic: _shade_gbuffer(  # noqa: E731
        tables, np.clip(albedo, 0.0, 1.0), roughness, metallic, export.normal, export.mask, directions)
    images = {
        "export": (on_export(export.albedo), export.mask),
        "truth_albedo": (on_export(true_albedo), export.mask),
        "truth_materials": (on_export(true_albedo, true_roughness, true_metallic), export.mask),
        "truth_geometry": (_shade_gbuffer(tables, mix(truth.albedo, export.albedo), mix(truth.roughness, export.roughness),
                                          mix(truth.metallic, export.metallic), truth.normal, truth.mask, directions), truth.mask),
        "truth_albedo_detail": (on_export(mix(export.albedo, export_coarse * truth_detail)), export.mask),
        "truth_albedo_coarse": (on_export(mix(export.albedo, truth_coarse * export_detail)), export.mask),
        "truth_roughness": (on_export(export.albedo, true_roughness), export.mask),
        "truth_albedo_roughness": (on_export(true_albedo, true_roughness), export.mask),
        "truth_albedo_metallic": (on_export(true_albedo, export.roughness, true_metallic), export.mask),
    }
    return {name: (box_downsample(image, supersample), box_downsample(coverage[..., None], supersample)[..., 0])
            for name, (image, coverage) in images.items()}


def exported_material_scores(export, truth) -> dict[str, float]:
    """The export's albedo (after the per-channel scale, as the evaluation's albedo PSNR), roughness
    and metallic PSNR against the truth's, on the pixels both G-buffers cover (RenderOutput-like, the
    same camera)."""
    both = (export.mask > 0.5) & (truth.mask > 0.5)
    if not both.any():
        return {key: float("nan") for key in EXPORTED_MATERIAL_KEYS}
    return {"exported_albedo_psnr": scaled_albedo_psnr(export.albedo, truth.albedo, both),
            "exported_roughness_psnr": psnr(export.roughness, truth.roughness, both),
            "exported_metallic_psnr": psnr(export.metallic, truth.metallic, both)}
