"""`lirm bench export`: seconds per export stage on this machine for a 20k-face asset (the issue's
target: under 20 s in all on the 2-core CPU): SDF sampling and marching cubes at 256^3, decimation,
xatlas unwrap, bake at 1024^2 and the .glb write.

The field is analytic (a vase-like lathe with a handle-like torus and the material patterns), so the
figure does not depend on trained weights; a LIRM field adds its own query cost to the SDF and
bake stages (reported separately by `lirm bench model`)."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import torch

from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.model.analytic_fields import SphereField


class BenchShape(SphereField):
    """A squashed sphere unioned with a torus: curved everywhere, with a hole (so xatlas cuts charts)."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        body = (points * torch.tensor([1.0, 1.0, 1.4])).norm(dim=-1) - 0.5
        q = torch.stack([(points[..., [0, 2]] - torch.tensor([0.55, 0.0])).norm(dim=-1) - 0.18, points[..., 1]], dim=-1)
        return torch.minimum(body, q.norm(dim=-1) - 0.06)


@dataclass(frozen=True)
class ExportBenchConfig:
    grid: int = 256
    faces: int = 20_000
    texture: int = 1024


def run_export_bench(config: ExportBenchConfig = ExportBenchConfig()) -> dict:
    export = ExportConfig(mesh=MeshExtractionConfig(resolution=config.grid, face_budget=config.faces), texture_size=config.texture)
    with tempfile.TemporaryDirectory() as tmp:
        result = export_field(BenchShape(), Path(tmp) / "bench.glb", export)
        size = (Path(tmp) / "bench.glb").stat().st_size
    seconds = {k: round(v, 2) for k, v in result.seconds.items()}
    return {"grid": config.grid, "faces": result.faces, "vertices": result.vertices, "texture": config.texture,
            "seconds": seconds, "total_seconds": round(sum(result.seconds.values()), 2), "glb_bytes": size}


@dataclass(frozen=True)
class RoundTripConfig:
    model: Path
    environment: str | Path = "studio"
    views: int = 4
    size: int = 256
    grid: int = 256
    faces: int = 20_000
    texture: int = 1024
    samples: int = 1_000_000  # surface samples of the model's field
    sheet: Path | None = None


def run_asset_round_trip(config: RoundTripConfig) -> dict:
    """A real PBR model as a field (synth/mesh_field.py), exported, reloaded and rendered against the
    original under an HDRI from orbit views: PSNR of the tone-mapped beauty and of the albedo."""
    import numpy as np

    from lirm.engine.assets.asset_source import resolve_asset
    from lirm.engine.assets.environment_files import resolve_environment
    from lirm.engine.io.images import to_uint8, write_png
    from lirm.engine.metrics import psnr
    from lirm.engine.orbit_render import normalizing_transform
    from lirm.engine.synth.mesh_field import MeshSampledField
    from lirm.engine.synth.object_views import protocol_cameras
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings

    model = resolve_asset(config.model)
    transform = normalizing_transform(model.bounds)
    transform[:3] *= 0.8
    field = MeshSampledField(model.meshes, transform, samples=config.samples)
    export = ExportConfig(mesh=MeshExtractionConfig(resolution=config.grid, face_budget=config.faces), texture_size=config.texture)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            result = export_field(field, Path(tmp) / "asset.glb", export, context=ctx)
            exported = resolve_asset(Path(tmp) / "asset.glb")
        azimuths = [360.0 * k / config.views + 20.0 for k in range(config.views)]
        cameras = protocol_cameras(azimuths, [20.0] * config.views, config.size, 50.0, 1.0)
        lighting = renderer.prepare_lighting(resolve_environment(config.environment))
        original_scene = renderer.upload(model.meshes, transform)
        exported_scene = renderer.upload(exported.meshes)
        settings = RenderSettings(supersample=2)
        rows, beauty_psnr, albedo_psnr = [[], []], [], []
        try:
            for camera in cameras:
                a = renderer.render_view(original_scene, camera, lighting, settings)
                b = renderer.render_view(exported_scene, camera, lighting, settings)
                both = (a.mask > 0.99) & (b.mask > 0.99)
                beauty_psnr.append(psnr(b.beauty, a.beauty))
                albedo_psnr.append(psnr(b.albedo, a.albedo, both))
                rows[0].append(a.beauty)
                rows[1].append(b.beauty)
        finally:
            original_scene.release()
            exported_scene.release()
            lighting.maps.release()
    finally:
        renderer.release()
        ctx.release()
    if config.sheet:
        sheet = np.concatenate([np.concatenate(r, axis=1) for r in rows], axis=0)
        write_png(config.sheet, to_uint8(sheet))
    return {"model": str(config.model), "environment": str(config.environment), "faces": result.faces,
            "texture": config.texture, "export_seconds": {k: round(v, 2) for k, v in result.seconds.items()},
            "beauty_psnr_per_view": [round(v, 2) for v in beauty_psnr], "beauty_psnr": round(float(np.mean(beauty_psnr)), 2),
            "albedo_psnr": round(float(np.mean(albedo_psnr)), 2), "sheet": str(config.sheet) if config.sheet else None}
