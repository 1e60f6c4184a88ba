"""The silhouette offset (silhouette_offset.py): at that distance outside a sphere's zero level, a ray
through the VolSDF density gathers an opacity of one half; a refined field's export is grown by it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.export.export_asset import ExportConfig, surface_extraction
from lirm.engine.export.field_mesh import MeshExtractionConfig, extract_field_mesh
from lirm.engine.export.silhouette_offset import silhouette_offset
from lirm.engine.model.analytic_fields import SphereField
from lirm.engine.model.field import volsdf_density


def _grazing_opacity(radius: float, miss: float, beta: float) -> float:
    """Opacity of a straight ray passing a sphere of `radius` at `miss` outside it, through the VolSDF
    density (scaled by 1/beta, as the renderer does), integrated finely along the ray."""
    s = torch.linspace(-1.0, 1.0, 400_001, dtype=torch.float64)
    distance = torch.sqrt((radius + miss) ** 2 + s**2) - radius
    depth = float((volsdf_density(distance, beta) / beta).sum() * (s[1] - s[0]))
    return 1.0 - math.exp(-depth)


@pytest.mark.parametrize("beta,radius", [(1 / 500, 0.3), (1 / 250, 0.3), (1 / 500, 0.6)])
def test_a_ray_that_far_outside_the_zero_level_is_half_opaque(beta, radius):
    offset = silhouette_offset(beta, radius)
    assert 2 * beta < offset < 5 * beta
    assert _grazing_opacity(radius, offset, beta) == pytest.approx(0.5, abs=0.06)
    assert _grazing_opacity(radius, offset - 2 * beta, beta) > 0.85 > 0.15 > _grazing_opacity(radius, offset + 2 * beta, beta)
    assert silhouette_offset(0.0) == 0.0


def test_a_refined_field_is_exported_where_its_silhouettes_are():
    field = SphereField(0.5)
    config = ExportConfig(mesh=MeshExtractionConfig(resolution=64, face_budget=None))
    assert surface_extraction(field, config).iso_level == 0.0  # a decoded update (no fitted beta): its zero level
    field.fitted_beta = 1 / 250
    level = surface_extraction(field, config).iso_level
    assert level == pytest.approx(silhouette_offset(1 / 250)) and level > 0.01
    grown = extract_field_mesh(field, surface_extraction(field, config))
    plain = extract_field_mesh(field, config.mesh)
    radius = lambda mesh: float(np.linalg.norm(mesh.vertices, axis=1).mean())  # noqa: E731
    assert radius(plain) == pytest.approx(0.5, abs=0.002)
    assert radius(grown) == pytest.approx(0.5 + level, abs=0.002)
    assert surface_extraction(field, replace(config, silhouette_correction=False)).iso_level == 0.0
