"""Marching cubes on a signed distance function, vectorised in numpy, with its case table derived
here rather than typed in.

The table: for each of the 256 inside/outside patterns of a cube's corners, the iso-surface crosses
the edges whose corners differ. On every cube face, walking its corners counter-clockwise as seen
from outside, each crossing into the inside starts an inside arc that ends at the next crossing;
the face's iso-line goes from that end back to its start. Each crossing is the end of a line on one
of its edge's two faces and the start of one on the other, so the lines chain into closed loops,
which are fanned into triangles. Ambiguous faces always keep inside corners apart, a rule that
depends only on the face's four corners, so neighbouring cubes agree and the mesh is watertight.

`extract_mesh` evaluates the SDF on a grid in chunks and returns triangles wound counter-clockwise
seen from outside (the SDF's positive side), the convention of glTF and our renderer.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np

# Corner c of the unit cube sits at (c & 1, c >> 1 & 1, c >> 2 & 1).
CORNERS = np.array([[c & 1, c >> 1 & 1, c >> 2 & 1] for c in range(8)], dtype=np.int64)
# Edge = (corner, corner + axis step): 4 along x, 4 along y, 4 along z.
EDGES = [(c, c | (1 << a)) for a in range(3) for c in range(8) if not c & (1 << a)]
EDGE_AXIS = np.array([a for a in range(3) for c in range(8) if not c & (1 << a)], dtype=np.int64)
EDGE_START = np.array([e[0] for e in EDGES], dtype=np.int64)


def _faces() -> list[list[int]]:
    """Each face's corners in counter-clockwise order seen from outside the cube."""
    faces = []
    for axis in range(3):
        u, v = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, 1):
            ring = [(0, 0), (1, 0), (1, 1), (0, 1)]  # counter-clockwise in (u, v) seen from +axis
            corners = [(side << axis) | (a << u) | (b << v) for a, b in ring]
            faces.append(corners if side == 1 else corners[::-1])  # seen from -axis the order flips
    return faces


@lru_cache(maxsize=1)
def case_table() -> np.ndarray:
    """(256, 5, 3) edge indices of each case's triangles, -1 padded (at most 5 triangles a case)."""
    edge_of = {frozenset(e): i for i, e in enumerate(EDGES)}
    table = -np.ones((256, 5, 3), dtype=np.int64)
    faces = _faces()
    for case in range(1, 255):
        inside = [(case >> c) & 1 == 1 for c in range(8)]
        following: dict[int, int] = {}  # iso-line start edge -> end edge
        for ring in faces:
            crossings = []  # (position on the ring, edge, entering the inside?)
            for k in range(4):
                a, b = ring[k], ring[(k + 1) % 4]
                if inside[a] != inside[b]:
                    crossings.append((k, edge_of[frozenset((a, b))], inside[b]))
            for j, (_, edge, entering) in enumerate(crossings):
                if entering:
                    arc_end = crossings[(j + 1) % len(crossings)][1]
                    following[arc_end] = edge
        triangles = []
        while following:
            start = next(iter(following))
            loop = [start]
            while following[loop[-1]] != start:
                loop.append(following.pop(loop[-1]))
            following.pop(loop[-1])
            triangles += [(loop[0], loop[i], loop[i + 1]) for i in range(1, len(loop) - 1)]
        table[case, :len(triangles)] = triangles
    return _wound_outward(table)


def _wound_outward(table: np.ndarray) -> np.ndarray:
    """Flip every triangle if the loops came out clockwise: checked on the one-corner case, where the
    outward direction (away from the inside corner 0) is unambiguous."""
    mid = (CORNERS[EDGE_START] + CORNERS[[e[1] for e in EDGES]]) / 2.0
    a, b, c = mid[table[1, 0]]
    if np.dot(np.cross(b - a, c - a), np.ones(3)) < 0:  # outward from corner 0 is +(1, 1, 1)
        table = table[:, :, ::-1].copy()
    return table


@dataclass
class ExtractedMesh:
    vertices: np.ndarray  # (V, 3) float32 world positions
    faces: np.ndarray  # (F, 3) int64, counter-clockwise seen from outside


def marching_cubes(values: np.ndarray, origin: np.ndarray, spacing: float, level: float = 0.0) -> ExtractedMesh:
    """The iso-surface `level` of samples values[i, j, k] at origin + (i, j, k) * spacing; inside is < level."""
    v = np.asarray(values, dtype=np.float64) - level
    n = np.array(v.shape) - 1
    if np.any(n < 1):
        raise ValueError(f"marching cubes needs at least 2 samples per axis, got {v.shape}")
    inside = v < 0
    case = np.zeros(tuple(n), dtype=np.int64)
    for c, (x, y, z) in enumerate(CORNERS):
        case |= inside[x:x + n[0], y:y + n[1], z:z + n[2]].astype(np.int64) << c
    cells = np.nonzero((case != 0) & (case != 255))
    if len(cells[0]) == 0:
        return ExtractedMesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int64))
    cell = np.stack(cells, axis=-1)  # (C, 3)
    tris = case_table()[case[cells]]  # (C, 5, 3) local edge indices
    valid = tris[:, :, 0] >= 0
    cell_of_tri = np.repeat(np.arange(len(cell)), 5).reshape(-1, 5)[valid]
    local_edges = tris[valid]  # (T, 3)
    # A global id per grid edge: its axis and its start sample, so neighbouring cubes share vertices.
    dims = np.array(v.shape)
    start = cell[cell_of_tri][:, None, :] + CORNERS[EDGE_START[local_edges]]  # (T, 3, 3)
    axis = EDGE_AXIS[local_edges]
    global_id = ((axis * dims[0] + start[..., 0]) * dims[1] + start[..., 1]) * dims[2] + start[..., 2]
    unique, faces = np.unique(global_id.reshape(-1), return_inverse=True)
    ax = unique // (dims[0] * dims[1] * dims[2])
    rest = unique % (dims[0] * dims[1] * dims[2])
    p0 = np.stack([rest // (dims[1] * dims[2]), rest // dims[2] % dims[1], rest % dims[2]], axis=-1)
    p1 = p0 + np.eye(3, dtype=np.int64)[ax]
    s0, s1 = v[tuple(p0.T)], v[tuple(p1.T)]
    t = np.clip(s0 / np.where(s0 == s1, 1e-12, s0 - s1), 0.0, 1.0)
    positions = (p0 + t[:, None] * (p1 - p0)) * spacing + np.asarray(origin, dtype=np.float64)
    faces = faces.reshape(-1, 3)
    # Zero-area triangles (two vertices on the same point) are dropped.
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return ExtractedMesh(positions.astype(np.float32), faces[keep])


def sample_sdf_grid(sdf: Callable[[np.ndarray], np.ndarray], resolution: int, radius: float,
                    chunk: int = 262_144) -> tuple[np.ndarray, np.ndarray, float]:
    """sdf (N, 3) -> (N,) evaluated at resolution^3 points spanning [-radius, radius]^3, in chunks.
    Returns (values, origin, spacing)."""
    if resolution < 2:
        raise ValueError(f"the grid resolution must be at least 2, got {resolution}")
    axis = np.linspace(-radius, radius, resolution)
    spacing = float(axis[1] - axis[0])
    total = resolution**3
    values = np.empty(total, dtype=np.float32)
    for begin in range(0, total, chunk):
        idx = np.arange(begin, min(begin + chunk, total))
        points = np.stack([axis[idx // (resolution * resolution)], axis[idx // resolution % resolution], axis[idx % resolution]], axis=-1)
        values[begin:begin + len(idx)] = np.asarray(sdf(points.astype(np.float32)), dtype=np.float32).reshape(-1)
    return values.reshape(resolution, resolution, resolution), np.full(3, -radius), spacing


def extract_mesh(sdf: Callable[[np.ndarray], np.ndarray], resolution: int, radius: float, level: float = 0.0) -> ExtractedMesh:
    values, origin, spacing = sample_sdf_grid(sdf, resolution, radius)
    return marching_cubes(values, origin, spacing, level)
