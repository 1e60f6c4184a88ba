"""A UV atlas for a mesh with xatlas, and per-vertex tangents for the normal map.

xatlas cuts the surface into charts, flattens and packs them into [0, 1]^2, duplicating vertices
along the seams. It is slow and single-threaded (DESIGN.md: ~8 s for 20k faces), so meshes are
decimated first and callers run it off the UI thread.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
import xatlas

from lirm.engine.errors import LirmUserError
from lirm.renderer.mesh import compute_tangents


@dataclass(frozen=True)
class AtlasConfig:
    texture_size: int = 1024
    padding: int = 4  # texels between charts (the bake dilates into them)


@dataclass
class UVMesh:
    positions: np.ndarray  # (V, 3) float32
    normals: np.ndarray  # (V, 3) float32 unit, smooth (area-weighted over the original vertex)
    uvs: np.ndarray  # (V, 2) float32 in [0, 1], v down (glTF)
    tangents: np.ndarray  # (V, 4) float32: unit tangent along +u, w = bitangent sign (glTF)
    faces: np.ndarray  # (F, 3) uint32, counter-clockwise from outside


def usable_vertex_normals(mesh: trimesh.Trimesh) -> np.ndarray:
    """trimesh's area-weighted vertex normals, with a unit normal wherever they are not one: a vertex
    whose faces all have zero area (marching cubes and decimation leave a few) gets a zero normal,
    which the renderer's G-buffer turns into NaN. Those take the direction from the mesh's centre,
    the outward normal of the closed, roughly star-shaped surfaces that reconstructions are."""
    normals = np.asarray(mesh.vertex_normals, np.float64).copy()
    length = np.linalg.norm(normals, axis=1)
    bad = ~np.isfinite(length) | (np.abs(length - 1.0) > 1e-3)
    if bad.any():
        vertices = np.asarray(mesh.vertices, np.float64)
        radial = vertices[bad] - vertices.mean(axis=0)
        r = np.linalg.norm(radial, axis=1, keepdims=True)
        normals[bad] = np.where(r > 1e-12, radial / np.maximum(r, 1e-12), np.array([0.0, 0.0, 1.0]))
    return normals.astype(np.float32)


def unwrap(mesh: trimesh.Trimesh, config: AtlasConfig = AtlasConfig()) -> UVMesh:
    if len(mesh.faces) == 0:
        raise LirmUserError("the mesh has no faces to unwrap; the surface extraction found nothing")
    areas = mesh.area_faces
    if not np.isfinite(mesh.vertices).all() or float(areas.sum()) <= 1e-12:
        raise LirmUserError("the mesh is degenerate (no area or non-finite vertices); xatlas cannot unwrap it. "
                            "Extract the surface again at a higher grid resolution")
    atlas = xatlas.Atlas()
    normals = usable_vertex_normals(mesh)
    atlas.add_mesh(np.asarray(mesh.vertices, np.float32), np.asarray(mesh.faces, np.uint32), normals)
    pack = xatlas.PackOptions()
    pack.resolution = config.texture_size
    pack.padding = config.padding
    pack.bilinear = True
    try:
        atlas.generate(pack_options=pack)
    except Exception as err:  # the binding raises RuntimeError on input it rejects
        raise LirmUserError(f"xatlas could not unwrap the mesh ({err}); extract it again with another face budget") from None
    if atlas.atlas_count != 1:
        raise LirmUserError(f"the UV atlas needs {atlas.atlas_count} textures of {config.texture_size}px; "
                            f"use a larger --texture or fewer --faces")
    vmapping, faces, uvs = atlas[0]
    positions = np.asarray(mesh.vertices, np.float32)[vmapping]
    vertex_normals = normals[vmapping]
    # The renderer's tangent convention (green = toward the image's top), so our previews and glTF viewers agree.
    tangents = compute_tangents(positions, vertex_normals, uvs, faces.astype(np.int64))
    return UVMesh(positions, vertex_normals, uvs.astype(np.float32), tangents, faces.astype(np.uint32))
