"""The narrow-band SDF grid gives marching cubes exactly the mesh of the dense grid, for fewer queries."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.export.field_mesh import field_sdf_grid
from lirm.engine.export.marching_cubes import marching_cubes, sample_sdf_grid
from lirm.engine.export.narrow_band import sample_sdf_narrow_band
from lirm.engine.model.analytic_fields import BoxField, SphereField
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM


class _Scaled:
    """An SDF multiplied by `scale`: steeper (> 1) or shallower (< 1) than a distance, as learnt SDFs are."""

    def __init__(self, field, scale: float):
        self.field, self.scale, self.radius = field, scale, field.radius

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return self.field.sdf(points) * self.scale


class _Specks(SphereField):
    """A sphere and a speck far smaller than a coarse cell, away from any coarse grid point."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        speck = (points - torch.tensor([0.71, -0.33, 0.52])).norm(dim=-1) - 0.03
        return torch.minimum(super().sdf(points), speck)


def _numpy_sdf(field):
    def sdf(points: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return field.sdf(torch.from_numpy(points)[None])[0].float().numpy()
    return sdf


def _random_lirm_field():
    torch.manual_seed(3)
    model = LIRM(preset("tiny")).eval()
    with torch.no_grad():
        state = model.initial_state(1)
        lumpy = replace(state, plane_tokens=30 * torch.randn_like(state.plane_tokens))  # blobs of surface, steep SDF
        return model.decode(lumpy)


FIELDS = {
    "sphere": lambda: SphereField(sphere_radius=0.5),
    "box": lambda: BoxField(half=(0.4, 0.3, 0.2)),
    "speck": lambda: _Specks(sphere_radius=0.4),
    "steep": lambda: _Scaled(BoxField(), 4.0),
    "shallow": lambda: _Scaled(SphereField(sphere_radius=0.6), 0.1),
    "untrained network": _random_lirm_field,
}


@pytest.mark.parametrize("name", list(FIELDS))
@pytest.mark.parametrize("resolution,stride", [(64, 4), (97, 4), (80, 8)])
def test_same_mesh_as_the_dense_grid(name, resolution, stride):
    field = FIELDS[name]()
    sdf = _numpy_sdf(field)
    dense, origin, spacing = sample_sdf_grid(sdf, resolution, float(field.radius))
    band = sample_sdf_narrow_band(sdf, resolution, float(field.radius), stride=stride)
    assert band.spacing == pytest.approx(spacing) and np.allclose(band.origin, origin)
    expected = marching_cubes(dense, origin, spacing)
    got = marching_cubes(band.values, band.origin, band.spacing)
    assert len(expected.faces) > 0
    np.testing.assert_array_equal(got.faces, expected.faces)
    np.testing.assert_allclose(got.vertices, expected.vertices, atol=1e-6)
    # Exact values where refined, and every cell the surface crosses is refined.
    np.testing.assert_allclose(band.values[band.refined], dense[band.refined], atol=1e-6)
    inside = dense < 0
    crossing = np.zeros_like(inside)
    for axis in range(3):
        change = np.diff(inside, axis=axis)
        lo = [slice(None)] * 3
        hi = [slice(None)] * 3
        lo[axis], hi[axis] = slice(0, -1), slice(1, None)
        crossing[tuple(lo)] |= change
        crossing[tuple(hi)] |= change
    assert band.refined[crossing].all()
    # A field this lumpy everywhere (the untrained network's) needs every sample; never more than the dense grid.
    assert band.evaluated < resolution**3 if name != "untrained network" else band.evaluated <= resolution**3


def test_fewer_queries_on_a_finer_grid():
    field = SphereField(sphere_radius=0.5)
    band = sample_sdf_narrow_band(_numpy_sdf(field), 160, 1.0)
    assert band.evaluated < 0.15 * 160**3


def test_nan_in_the_field_is_reported_not_hidden():
    class Broken(SphereField):
        def sdf(self, points):
            s = super().sdf(points)
            return torch.where(points[..., 0] > 0.6, torch.full_like(s, float("nan")), s)

    from lirm.engine.errors import LirmUserError

    with pytest.raises(LirmUserError, match="NaN"):
        field_sdf_grid(Broken(sphere_radius=0.5), 48, narrow_band_stride=4)


def test_bad_arguments():
    with pytest.raises(ValueError, match="stride"):
        sample_sdf_narrow_band(lambda p: p[:, 0], 16, 1.0, stride=0)
    with pytest.raises(ValueError, match="resolution"):
        sample_sdf_narrow_band(lambda p: p[:, 0], 1, 1.0)
