"""The model half of next-view guidance: where the reconstruction is unsure, per surface vertex.

Three signs, each scaled to [0, 1] over the surface and averaged:
- change: how much the SDF and albedo at the vertex moved between the last two updates (what new
  views still change is what the views so far did not pin down);
- view dependence: how much the NDE colour varies over directions around the normal (glossy
  regions need more views to separate reflection from albedo);
- low opacity: how much light would pass through the surface at the vertex, crossing it along the
  normal with the renderer's density (1 - opacity over a short segment): a surface the field barely
  commits to (a thin or faint shell) is one the views have not pinned down. Unlike the other two it
  is not rescaled over the surface, since a fully opaque surface should add nothing.
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
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)  # a degenerate vertex's zero normal stays zero, not NaN
    b = np.cross(n, t)
    colours = []
    for k in range(directions):
        a = 2 * np.pi * k / directions
        view = -(n + np.cos(a) * t + np.sin(a) * b) / np.sqrt(2.0)  # rays travel toward the surface
        sample = fields[-1].sample(p, torch.from_numpy(view.astype(np.float32))[None])
        colours.append(sample.colour[0].float().numpy())
    out["view_dependence"] = _unit_scale(np.stack(colours).std(axis=0).mean(axis=-1))
    # Crossing any zero level, however thin, the density's two tails alone give an opacity of 1 - 1/e;
    # measured against that, a film is near 1 and a solid surface 0.
    out["low_opacity"] = np.clip((1.0 - surface_opacity(fields[-1], vertices, n)) * np.e, 0.0, 1.0)
    out["total"] = (out["change"] + out["view_dependence"] + out["low_opacity"]) / 3.0
    return out


@torch.no_grad()
def surface_opacity(field, vertices: np.ndarray, normals: np.ndarray, half_length: float = 0.05, samples: int = 24,
                    beta: float | None = None) -> np.ndarray:
    """(V,) opacity of the field along a segment of 2 x half_length through each vertex along its
    normal, with the volume renderer's density (VolSDF, beta as at the end of training by default)."""
    from lirm.engine.model.field import volsdf_density
    from lirm.engine.model.volume_renderer import VolumeRenderConfig

    beta = VolumeRenderConfig().beta if beta is None else beta
    offsets = np.linspace(half_length, -half_length, samples)
    step = 2.0 * half_length / (samples - 1)
    unit = np.asarray(normals, np.float64) / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    points = np.asarray(vertices, np.float64)[:, None, :] + offsets[None, :, None] * unit[:, None, :]  # (V, S, 3)
    sdf = field.sdf(torch.from_numpy(points.reshape(1, -1, 3).astype(np.float32)))[0].reshape(len(unit), samples)
    sigma = volsdf_density(sdf.float(), beta) / beta
    return (1.0 - torch.exp(-sigma.sum(dim=1) * step)).numpy().astype(np.float64)


def guidance_weights(uncertainty: np.ndarray, strength: float = 2.0) -> np.ndarray:
    return 1.0 + strength * np.asarray(uncertainty, np.float64)
