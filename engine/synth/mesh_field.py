"""A field sampled from a real PBR model: the "ground-truth reconstruction" of an asset, for checking
export on real geometry and textures without trained weights.

The model's surface is sampled densely (area-uniform points with their normal and material looked up
in the textures: base colour sRGB -> linear, roughness from G and metallic from B of
metallicRoughness, times the factors). A query point takes the nearest sample's materials; its SDF is
the distance to that sample, signed by the side of the nearest samples' normals it lies on (a vote). Good to a fraction
of the sample spacing on closed models; open or self-intersecting models give local sign errors.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from lirm.engine.model.field import FieldSample
from lirm.renderer.mesh import MeshData
from lirm.renderer.tonemap import srgb_to_linear


def _lookup(texture: np.ndarray | None, uv: np.ndarray) -> np.ndarray | None:
    """Nearest-texel lookup with glTF's uv (v down), wrapping."""
    if texture is None or uv is None:
        return None
    h, w = texture.shape[:2]
    x = np.mod(np.floor(uv[:, 0] * w), w).astype(np.int64)
    y = np.mod(np.floor(uv[:, 1] * h), h).astype(np.int64)
    return texture[y, x].astype(np.float32) / 255.0


class MeshSampledField:
    def __init__(self, meshes: list[MeshData], transform: np.ndarray, samples: int = 1_000_000, seed: int = 0,
                 radius: float = 1.0):
        self.radius = radius
        self.normal_eps = 2e-3
        rng = np.random.default_rng(seed)
        parts = {"p": [], "n": [], "albedo": [], "roughness": [], "metallic": []}
        areas = []
        for m in meshes:
            v = np.c_[m.positions, np.ones(len(m.positions))] @ transform.T
            tri = v[:, :3][m.indices]
            areas.append(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1))
        total = sum(a.sum() for a in areas)
        for m, a in zip(meshes, areas):
            count = int(round(samples * a.sum() / total))
            if count == 0:
                continue
            faces = rng.choice(len(a), size=count, p=a / a.sum())
            r1, r2 = rng.random(count), rng.random(count)
            s = np.sqrt(r1)
            bary = np.stack([1 - s, s * (1 - r2), s * r2], axis=1)
            idx = m.indices[faces]
            v = np.c_[m.positions, np.ones(len(m.positions))] @ transform.T
            parts["p"].append(np.einsum("nk,nkc->nc", bary, v[:, :3][idx]))
            rotation = transform[:3, :3] / np.cbrt(abs(np.linalg.det(transform[:3, :3])))
            normals = np.einsum("nk,nkc->nc", bary, m.normals[idx]) @ rotation.T
            parts["n"].append(normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12))
            uv = np.einsum("nk,nkc->nc", bary, m.uvs[idx]) if m.uvs is not None else None
            mat = m.material
            base = np.tile(np.asarray(mat.base_color_factor[:3], np.float32), (count, 1))
            tex = _lookup(mat.base_color_texture, uv)
            if tex is not None:
                base = base * srgb_to_linear(tex[:, :3]).astype(np.float32)
            rough = np.full(count, mat.roughness_factor, np.float32)
            metal = np.full(count, mat.metallic_factor, np.float32)
            mr = _lookup(mat.metallic_roughness_texture, uv)
            if mr is not None:
                rough, metal = rough * mr[:, 1], metal * mr[:, 2]
            parts["albedo"].append(base)
            parts["roughness"].append(rough)
            parts["metallic"].append(metal)
        self.points = np.concatenate(parts["p"]).astype(np.float32)
        self.normals = np.concatenate(parts["n"]).astype(np.float32)
        self.albedo = np.concatenate(parts["albedo"]).astype(np.float32)
        self.roughness = np.concatenate(parts["roughness"]).astype(np.float32)
        self.metallic = np.concatenate(parts["metallic"]).astype(np.float32)
        self.tree = cKDTree(self.points)
        # Far from the surface a nearest-neighbour search visits many leaves of the dense tree; a
        # sparse tree answers those queries (their distance needs no precision), the dense one the rest.
        self.coarse_index = np.arange(0, len(self.points), 64)
        self.coarse_tree = cKDTree(self.points[self.coarse_index])
        self.band = 0.05 * radius

    def _nearest(self, points: torch.Tensor, votes: int = 8) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(points, signed distance, nearest sample). The sign is the majority over the `votes` nearest
        samples' normals: one sample's normal flips the sign near thin or open parts."""
        p = points.detach().reshape(-1, 3).cpu().numpy().astype(np.float64)
        distance, coarse = self.coarse_tree.query(p, k=votes, workers=-1)
        index = self.coarse_index[coarse]
        near = distance[:, 0] < self.band
        if near.any():
            distance[near], index[near] = self.tree.query(p[near], k=votes, workers=-1)
        side = np.sign(np.einsum("nkc,nkc->nk", p[:, None] - self.points[index], self.normals[index])).sum(axis=1)
        return p, np.where(side < 0, -1.0, 1.0) * distance[:, 0], index[:, 0]

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        _, s, _ = self._nearest(points)
        return torch.from_numpy(s.astype(np.float32)).reshape(points.shape[:-1])

    def sample(self, points: torch.Tensor, view_dirs: torch.Tensor | None = None) -> FieldSample:
        _, s, i = self._nearest(points)
        shape = points.shape[:-1]

        def t(a: np.ndarray, *tail: int) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a)).reshape(*shape, *tail)

        albedo = t(self.albedo[i], 3)
        return FieldSample(sdf=t(s.astype(np.float32)), albedo=albedo, roughness=t(self.roughness[i]),
                           metallic=t(self.metallic[i]), normal=t(self.normals[i], 3),
                           colour=None if view_dirs is None else albedo)
