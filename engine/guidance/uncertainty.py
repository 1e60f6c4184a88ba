"""The model half of next-view guidance: where the reconstruction is unsure, per surface vertex.

Three signs, each scaled to [0, 1] over the surface and averaged:
- change: how much the SDF and albedo at the vertex moved between the last two updates (what new
  views still change is what the views so far did not pin down);
- view dependence: how much the NDE colour varies over directions around the normal (glossy
  regions need more views to separate reflection from albedo);
- thin evidence: how close the vertex is to the surface's edge of confidence, measured as a soft SDF
  magnitude at the vertex (a vertex far from the field's own zero level is poorly supported).
The guidance weight of a vertex is 1 + strength x uncertainty, so coverage always counts.
"""

from __future__ import annotations

import numpy as np
import torch


def _unit_scale(a: np.ndarray) -> np.ndarray:
    lo, hi = float(np.min(a)), float(np.max(a))
    return np.zeros_like(a) if hi - lo < 1e-12 else (a - lo) / (hi - lo)


@torch.no_grad()
def vertex_uncertainty(fields: list, vertices: np.ndarray, normals: np.ndarray, directions: int = 6) -> dict[str, np.ndarray]:
    """fields: decoded fields after successive updates (oldest first; at least one)."""
    if not fields:
        raise ValueError("need the field of at least one update")
    p = torch.from_numpy(np.asarray(vertices, np.float32))[None]
    n = np.asarray(normals, np.float64)
    last = fields[-1].sample(p, None)
    out = {}
    if len(fields) > 1:
        previous = fields[-2].sample(p, None)
        change = (last.sdf - previous.sdf).abs()[0] + (last.albedo - previous.albedo).abs().mean(-1)[0]
        out["change"] = _unit_scale(change.float().numpy())
    else:
        out["change"] = np.zeros(len(vertices))
    # Viewing directions tilted 45 degrees from the normal, spread around it.
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    colours = []
    for k in range(directions):
        a = 2 * np.pi * k / directions
        view = -(n + np.cos(a) * t + np.sin(a) * b) / np.sqrt(2.0)  # rays travel toward the surface
        sample = fields[-1].sample(p, torch.from_numpy(view.astype(np.float32))[None])
        colours.append(sample.colour[0].float().numpy())
    out["view_dependence"] = _unit_scale(np.stack(colours).std(axis=0).mean(axis=-1))
    out["thin_evidence"] = _unit_scale(np.abs(last.sdf[0].float().numpy()))
    out["total"] = (out["change"] + out["view_dependence"] + out["thin_evidence"]) / 3.0
    return out


def guidance_weights(uncertainty: np.ndarray, strength: float = 2.0) -> np.ndarray:
    return 1.0 + strength * np.asarray(uncertainty, np.float64)
