"""Chamfer distance between surfaces, as point samples (the paper's CD column)."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import cKDTree


def surface_samples(vertices: np.ndarray, faces: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """`count` points uniformly over the triangles' area (seeded)."""
    if len(faces) == 0:
        return np.zeros((0, 3), np.float32)
    mesh = trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces), process=False)
    points, _ = trimesh.sample.sample_surface(mesh, count, seed=seed)
    return np.asarray(points, np.float32)


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Mean nearest-neighbour distance from a to b plus from b to a, halved (symmetric, in scene units).
    Infinite when either set is empty (nothing was reconstructed)."""
    if len(a) == 0 or len(b) == 0:
        return float("inf")
    d_ab, _ = cKDTree(b).query(a)
    d_ba, _ = cKDTree(a).query(b)
    return float(0.5 * (d_ab.mean() + d_ba.mean()))
