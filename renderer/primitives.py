"""Simple analytic meshes: material preview spheres, quads and boxes (also the tests' fixtures)."""

from __future__ import annotations

import numpy as np

from .material import PBRMaterial
from .mesh import MeshData


def uv_sphere(radius: float = 1.0, segments: int = 64, material: PBRMaterial | None = None, center=(0.0, 0.0, 0.0)) -> MeshData:
    """Latitude-longitude sphere around +Z; u follows the azimuth from +X, v runs from the north pole down."""
    theta = np.linspace(0.0, np.pi, segments + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, 2 * segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    unit = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), t / np.pi], axis=-1).reshape(-1, 2)
    cols = 2 * segments + 1
    i, j = np.meshgrid(np.arange(segments), np.arange(2 * segments), indexing="ij")
    a = (i * cols + j).ravel()
    b = a + cols
    faces = np.concatenate([np.stack([a, b, a + 1], 1), np.stack([a + 1, b, b + 1], 1)])
    return MeshData(unit * radius + np.asarray(center, dtype=np.float64), faces, normals=unit, uvs=uv,
                    material=material or PBRMaterial(), name="sphere")


def quad(size: float = 2.0, material: PBRMaterial | None = None, subdivisions: int = 1) -> MeshData:
    """A square in the z = 0 plane facing +Z. uv (0, 0) is the (-x, +y) corner: u runs along +x and
    v along -y, so the texture reads upright when seen from above with +y up."""
    n = subdivisions + 1
    s = np.linspace(0.0, 1.0, n)
    u, v = np.meshgrid(s, s)  # rows follow v
    positions = np.stack([(u - 0.5) * size, (0.5 - v) * size, np.zeros_like(u)], -1).reshape(-1, 3)
    uvs = np.stack([u, v], -1).reshape(-1, 2)
    r, c = np.meshgrid(np.arange(subdivisions), np.arange(subdivisions), indexing="ij")
    a = (r * n + c).ravel()
    faces = np.concatenate([np.stack([a, a + n, a + n + 1], 1), np.stack([a, a + n + 1, a + 1], 1)])
    normals = np.tile(np.array([[0.0, 0.0, 1.0]]), (len(positions), 1))
    return MeshData(positions, faces, normals=normals, uvs=uvs, material=material or PBRMaterial(), name="quad")
