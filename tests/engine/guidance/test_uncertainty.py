import numpy as np
import torch
import trimesh

from lirm.engine.guidance.uncertainty import guidance_weights, surface_opacity, vertex_uncertainty
from lirm.engine.model.analytic_fields import SphereField
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM, ReconState


def _field(model, seed: int):
    g = torch.Generator().manual_seed(seed)
    c = model.config
    state = ReconState(torch.randn(1, c.num_plane_tokens, c.width, generator=g),
                       torch.randn(1, c.num_nde_tokens, c.width, generator=g), 1, c.signature())
    return model.decode(state)


def test_change_between_updates_and_view_dependence_are_measured():
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).eval()
    sphere = trimesh.creation.icosphere(2, radius=0.5)
    a, b = _field(model, 1), _field(model, 2)
    same = vertex_uncertainty([a, a], sphere.vertices, sphere.vertex_normals)
    assert np.all(same["change"] == 0)  # nothing moved between identical updates
    moved = vertex_uncertainty([a, b], sphere.vertices, sphere.vertex_normals)
    assert moved["change"].max() == 1.0 and moved["change"].min() == 0.0
    for key in ("view_dependence", "low_opacity", "total"):
        assert moved[key].shape == (len(sphere.vertices),) and 0 <= moved[key].min() and moved[key].max() <= 1
    single = vertex_uncertainty([b], sphere.vertices, sphere.vertex_normals)
    assert np.all(single["change"] == 0)
    w = guidance_weights(moved["total"])
    assert w.min() >= 1.0 and w.max() <= 3.0


class _SphereAndFilm(SphereField):
    """A solid sphere, and above it a film 0.002 thick: a surface the field barely commits to."""

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        film = torch.maximum((points[..., 2] - 0.7).abs() - 0.001, points[..., :2].norm(dim=-1) - 0.3)
        return torch.minimum(super().sdf(points), film)


def test_a_faint_film_is_uncertain_and_a_solid_surface_is_not():
    field = _SphereAndFilm(sphere_radius=0.4)
    on_sphere = np.array([[0.4, 0.0, 0.0], [0.0, -0.4, 0.0], [0.0, 0.0, -0.4]])
    on_film = np.array([[0.0, 0.0, 0.701], [0.1, 0.1, 0.701]])
    points = np.concatenate([on_sphere, on_film])
    normals = np.concatenate([on_sphere / 0.4, [[0.0, 0.0, 1.0]] * 2])
    opacity = surface_opacity(field, points, normals)
    assert np.all(opacity[:3] > 0.99)
    assert np.all(opacity[3:] < 0.8)  # the density's tails alone give 1 - 1/e = 0.63
    total = vertex_uncertainty([field], points, normals)
    assert total["low_opacity"][3:].min() > total["low_opacity"][:3].max() + 0.4
