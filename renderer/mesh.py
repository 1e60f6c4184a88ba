"""Triangle meshes as numpy data, plus the vertex attributes the PBR shader needs.

World frame: right-handed, +Z up (DESIGN.md §3). Loaders convert into it before building MeshData.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .material import PBRMaterial


@dataclass
class MeshData:
    positions: np.ndarray  # (V, 3) float32, world space
    indices: np.ndarray  # (F, 3) uint32, counter-clockwise front faces
    normals: np.ndarray | None = None  # (V, 3) float32 unit; computed when absent
    uvs: np.ndarray | None = None  # (V, 2) float32, glTF convention (v down from the image top)
    tangents: np.ndarray | None = None  # (V, 4) float32: xyz unit tangent, w = bitangent sign
    colors: np.ndarray | None = None  # (V, 4) float32 linear RGBA vertex colours (COLOR_0)
    material: PBRMaterial = field(default_factory=PBRMaterial)
    name: str = "mesh"

    def __post_init__(self) -> None:
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.indices = np.ascontiguousarray(self.indices, dtype=np.uint32).reshape(-1, 3)
        n = len(self.positions)
        if len(self.indices) and int(self.indices.max()) >= n:
            raise ValueError(f"{self.name}: face index {int(self.indices.max())} out of range for {n} vertices")
        if not np.isfinite(self.positions).all():
            raise ValueError(f"{self.name}: vertex positions contain NaN or infinity")
        for attr, width in (("normals", 3), ("uvs", 2), ("tangents", 4), ("colors", 4)):
            value = getattr(self, attr)
            if value is None:
                continue
            value = np.ascontiguousarray(value, dtype=np.float32)
            if value.shape != (n, width):
                raise ValueError(f"{self.name}: {attr} has shape {value.shape}, expected ({n}, {width})")
            setattr(self, attr, value)
        if self.normals is None:
            self.normals = compute_vertex_normals(self.positions, self.indices)
        if self.tangents is None and self.uvs is not None and self.material.normal_texture is not None:
            self.tangents = compute_tangents(self.positions, self.normals, self.uvs, self.indices)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned min and max corner."""
        return np.stack([self.positions.min(0), self.positions.max(0)])


def compute_vertex_normals(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Area-weighted smooth vertex normals."""
    p = positions.astype(np.float64)
    tri = p[indices]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area
    normals = np.zeros_like(p)
    for k in range(3):
        np.add.at(normals, indices[:, k], face_n)
    return _normalize(normals, fallback=np.array([0.0, 0.0, 1.0])).astype(np.float32)


def compute_tangents(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Per-vertex tangent frames from UV gradients (Lengyel's method, as MikkTSpace does per face).

    glTF's v axis points down the image while the tangent-space normal map's green channel points
    up (+Y = bitangent toward decreasing v), so the bitangent is the direction of -dv.
    """
    p = positions.astype(np.float64)
    uv = uvs.astype(np.float64)
    n = normals.astype(np.float64)
    e1 = p[indices[:, 1]] - p[indices[:, 0]]
    e2 = p[indices[:, 2]] - p[indices[:, 0]]
    d1 = uv[indices[:, 1]] - uv[indices[:, 0]]
    d2 = uv[indices[:, 2]] - uv[indices[:, 0]]
    # Flip v so that the bitangent follows the image's upward direction (normal-map green).
    d1[:, 1] *= -1.0
    d2[:, 1] *= -1.0
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    sdir = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r  # d position / d u
    tdir = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r  # d position / d v_up
    tan = np.zeros_like(p)
    bit = np.zeros_like(p)
    for k in range(3):
        np.add.at(tan, indices[:, k], sdir)
        np.add.at(bit, indices[:, k], tdir)
    # Gram-Schmidt against the normal; fall back to any perpendicular where UVs are degenerate.
    t = tan - n * np.sum(n * tan, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    fallback = np.cross(n, helper)
    t = np.where(np.linalg.norm(t, axis=1, keepdims=True) > 1e-12, t, fallback)
    t = _normalize(t, fallback=np.array([1.0, 0.0, 0.0]))
    w = np.where(np.sum(np.cross(n, t) * bit, axis=1) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1).astype(np.float32)


def _normalize(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(length > 1e-20, v / np.maximum(length, 1e-20), fallback)
