"""The baked normal map on analytic fields whose true normal is known: where the surface is smooth
the tangent-space normal is flat (0, 0, 1) up to the mesh's facets (issue 21, case 10)."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.model.analytic_fields import BoxField, SphereField


def _tilt_degrees(textures) -> np.ndarray:
    n = textures.normal[textures.covered]
    return np.degrees(np.arccos(np.clip(n[:, 2], -1.0, 1.0)))


def test_a_sphere_bakes_a_flat_normal_map(tmp_path, gl_context):
    result = export_field(SphereField(sphere_radius=0.55), tmp_path / "sphere.glb",
                          ExportConfig(mesh=MeshExtractionConfig(resolution=96, face_budget=5000), texture_size=512),
                          context=gl_context)
    tilt = _tilt_degrees(result.textures)
    # Measured: median 0.23 degrees, 95th percentile 0.96 (the facets of a 5000-face sphere).
    assert np.median(tilt) < 1.0 and np.percentile(tilt, 95) < 3.0 and (tilt > 60).mean() == 0.0


def test_a_box_bakes_flat_faces(tmp_path, gl_context):
    result = export_field(BoxField(half=(0.45, 0.35, 0.3)), tmp_path / "box.glb",
                          ExportConfig(mesh=MeshExtractionConfig(resolution=96, face_budget=5000), texture_size=512),
                          context=gl_context)
    tilt = _tilt_degrees(result.textures)
    # Marching cubes bevels the edges by a voxel: only the faces' inner parts are flat.
    assert np.median(tilt) < 2.0, np.median(tilt)


class _SphereWithAWrongShadingNormal(SphereField):
    """A sphere whose predicted shading normal points straight up everywhere (as a poorly trained
    normal head does): the geometry is right, the head is not."""

    def sample(self, points, view_dirs=None):
        sample = super().sample(points, view_dirs)
        up = torch.zeros_like(sample.normal)
        up[..., 2] = 1.0
        return dataclasses.replace(sample, normal=up)


def test_the_normal_map_follows_the_geometry_not_the_shading_head(tmp_path, gl_context):
    from lirm.engine.export.texture_bake import BakeConfig

    tilts = {}
    for source in ("sdf", "head"):
        config = ExportConfig(mesh=MeshExtractionConfig(resolution=64, face_budget=3000), texture_size=256,
                              bake=BakeConfig(normal_source=source))
        result = export_field(_SphereWithAWrongShadingNormal(sphere_radius=0.55), tmp_path / f"{source}.glb", config,
                              context=gl_context)
        tilts[source] = _tilt_degrees(result.textures)
    assert np.median(tilts["sdf"]) < 1.5
    assert np.median(tilts["head"]) > 30.0  # the head's error would have been baked in
