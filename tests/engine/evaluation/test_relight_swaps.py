"""The swap study (relight_swaps.py): an export whose only fault is its albedo. Swapping in the truth's
albedo (or all its materials) relights it as the truth; swapping in the truth's geometry, the same
sphere, changes nothing; the unswapped shading equals the renderer's own relit export; the export's
own materials are scored against the truth's in the same G-buffers."""

from __future__ import annotations

import numpy as np
import torch

from lirm.engine.cameras import Camera, look_at
from lirm.engine.evaluation.relight_swaps import SWAPS, exported_material_scores, swapped_images
from lirm.engine.evaluation.relighting import RELIGHT_SUPERSAMPLE, relight_metrics, render_relight_truth
from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.export.photo_texture_fit import mesh_for_rendering
from lirm.engine.lighting.lighting_tables import tables_from_lighting
from lirm.engine.model.analytic_fields import MaterialPattern, SphereField
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.procedural_environments import make_procedural_environment

SMALL = ExportConfig(mesh=MeshExtractionConfig(resolution=48, face_budget=3000), texture_size=128)


class _Dielectric(MaterialPattern):
    def metallic(self, p: torch.Tensor) -> torch.Tensor:
        return torch.zeros(p.shape[:-1], dtype=p.dtype, device=p.device)


def test_swapping_in_the_true_albedo_fixes_an_export_whose_albedo_is_wrong(tmp_path, renderer, gl_context):
    checker = _Dielectric(colour_a=(0.8, 0.25, 0.1), colour_b=(0.1, 0.3, 0.7), checker=0.3, roughness_range=(0.5, 0.5))
    grey = _Dielectric(colour_a=(0.4, 0.4, 0.4), colour_b=(0.4, 0.4, 0.4), roughness_range=(0.5, 0.5))
    truth = export_field(SphereField(0.5, pattern=checker), tmp_path / "truth.glb", SMALL, context=gl_context)
    export = export_field(SphereField(0.5, pattern=grey), tmp_path / "export.glb", SMALL, context=gl_context)
    cameras = [Camera.from_fov(48, 48, 40.0, look_at((2.5 * np.cos(a), 2.5 * np.sin(a), 0.8), (0, 0, 0))) for a in (0.3, 2.4)]
    environment = make_procedural_environment("studio", width=128)
    relit = render_relight_truth(renderer, [mesh_for_rendering(truth.uv_mesh, truth.textures)], np.eye(4), cameras, [0, 1],
                                 environment, 30.0, 0.0, keep_gbuffers=True)
    assert set(relit.gbuffers) == {0, 1} and relit.gbuffers[0].albedo.shape == (96, 96, 3)
    scene = renderer.upload([mesh_for_rendering(export.uv_mesh, export.textures)])
    lighting = renderer.prepare_lighting(environment, rotation_deg=30.0)
    try:
        tables = tables_from_lighting(renderer, lighting)
        scores = {name: [] for name in SWAPS}
        for i, camera in enumerate(cameras):
            fine = camera.scaled(RELIGHT_SUPERSAMPLE)
            gbuffer = renderer.render_view(scene, fine, lighting, RenderSettings(show_environment=False, supersample=1))
            images = swapped_images(gbuffer, relit.gbuffers[i], tables, fine.pixel_rays()[1], RELIGHT_SUPERSAMPLE)
            # The export's own materials: its roughness and metallic are the truth's (0.5, 0), its albedo grey.
            exported = exported_material_scores(gbuffer, relit.gbuffers[i])
            assert exported["exported_roughness_psnr"] > 40 and exported["exported_metallic_psnr"] > 40, exported
            assert exported["exported_albedo_psnr"] < 20, exported
            assert exported_material_scores(relit.gbuffers[i], relit.gbuffers[i])["exported_albedo_psnr"] > 40
            assert set(images) == set(SWAPS) and images["export"][0].shape == (48, 48, 3)
            for name, (radiance, coverage) in images.items():
                scores[name].append(relight_metrics(radiance, coverage, relit.radiance[i], relit.mask[i], 0.0)["relight_psnr_l"])
            # The torch twin's unswapped shading is the renderer's own relit export.
            rendered = renderer.render_view(scene, camera, lighting, RenderSettings(show_environment=False, supersample=2))
            own = relight_metrics(rendered.radiance, rendered.mask, relit.radiance[i], relit.mask[i], 0.0)["relight_psnr_l"]
            assert abs(own - scores["export"][-1]) < 0.3, (own, scores["export"][-1])
    finally:
        scene.release()
        lighting.maps.release()
    mean = {name: float(np.mean(v)) for name, v in scores.items()}
    assert mean["truth_albedo"] > mean["export"] + 10 and mean["truth_materials"] > mean["export"] + 10, mean
    assert abs(mean["truth_geometry"] - mean["export"]) < 1.5, mean  # the same sphere: nothing to gain
    # Roughness and metallic are the truth's already (0.5, 0): swapping them in changes nothing.
    assert abs(mean["truth_roughness"] - mean["export"]) < 0.1, mean
    assert abs(mean["truth_albedo_roughness"] - mean["truth_albedo"]) < 0.1, mean
    assert abs(mean["truth_albedo_metallic"] - mean["truth_albedo"]) < 0.1, mean
    # The grey export has no detail of its own: the truth's detail on it is most of the way to the truth's albedo.
    assert mean["truth_albedo_detail"] > mean["export"] + 3, mean
