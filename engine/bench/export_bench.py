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
