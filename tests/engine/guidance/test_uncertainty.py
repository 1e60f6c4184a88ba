import numpy as np
import torch
import trimesh

from lirm.engine.guidance.uncertainty import guidance_weights, vertex_uncertainty
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
    for key in ("view_dependence", "thin_evidence", "total"):
        assert moved[key].shape == (len(sphere.vertices),) and 0 <= moved[key].min() and moved[key].max() <= 1
    single = vertex_uncertainty([b], sphere.vertices, sphere.vertex_normals)
    assert np.all(single["change"] == 0)
    w = guidance_weights(moved["total"])
    assert w.min() >= 1.0 and w.max() <= 3.0
