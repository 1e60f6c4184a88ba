"""Field -> clean mesh on analytic fields: the right surface, floaters gone, decimated to budget."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.export.field_mesh import MeshExtractionConfig, NoSurfaceError, extract_field_mesh
from lirm.engine.model.analytic_fields import BoxField, SphereField


class _SphereWithFloaters(SphereField):
    """A sphere plus two specks of surface far from it (what a reconstruction leaves in empty space)."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        main = super().sdf(points)
        specks = [(points - torch.tensor(c)).norm(dim=-1) - 0.04 for c in ((0.8, 0.0, 0.0), (0.0, -0.75, 0.3))]
        return torch.minimum(main, torch.minimum(*specks))


def test_box_surface_lies_on_the_box():
    field = BoxField(half=(0.4, 0.3, 0.2))
    mesh = extract_field_mesh(field, MeshExtractionConfig(resolution=64, face_budget=None))
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(0.8 * 0.6 * 0.4, rel=0.03)
    distance = field.sdf(torch.from_numpy(np.asarray(mesh.vertices, np.float32))).abs()
    assert float(distance.max()) < 2.0 / 63  # within a voxel of the true surface
    np.testing.assert_allclose(mesh.bounds, [[-0.4, -0.3, -0.2], [0.4, 0.3, 0.2]], atol=0.03)


def test_floaters_are_removed_and_the_budget_is_kept():
    field = _SphereWithFloaters(sphere_radius=0.5)
    raw = extract_field_mesh(field, MeshExtractionConfig(resolution=96, face_budget=None, floater_fraction=0.0))
    assert len(raw.split(only_watertight=False)) == 3
    clean = extract_field_mesh(field, MeshExtractionConfig(resolution=96, face_budget=2000))
    assert len(clean.split(only_watertight=False)) == 1
    assert len(clean.faces) <= 2000 and clean.is_watertight
    radii = np.linalg.norm(clean.vertices, axis=1)
    assert radii.min() > 0.47 and radii.max() < 0.53  # decimation kept the silhouette
    # Smooth normals point outward.
    assert np.mean(np.sum(clean.vertex_normals * clean.vertices, axis=1) > 0) > 0.99


def test_empty_or_all_inside_fields_say_there_is_nothing_to_extract():
    with pytest.raises(NoSurfaceError, match="positive everywhere"):
        extract_field_mesh(SphereField(sphere_radius=0.0001, center=(5.0, 5.0, 5.0)), MeshExtractionConfig(resolution=16))
    with pytest.raises(NoSurfaceError, match="negative everywhere"):
        extract_field_mesh(SphereField(sphere_radius=10.0), MeshExtractionConfig(resolution=16))
