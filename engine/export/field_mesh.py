"""The surface of a field as a clean triangle mesh: marching cubes on the SDF (queried in chunks),
the main component kept and floaters dropped, then decimated to a face budget by quadric error
(which keeps the silhouette: flat regions lose triangles first), with smooth vertex normals.

Works on any field with `sdf(points (1, N, 3)) -> (1, N)` and `radius`: the decoded LIRM field or
the analytic ones (engine/model/analytic_fields.py), so every step is checked without trained weights.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch
import trimesh

from lirm.engine.errors import LirmUserError
from lirm.engine.model.field import device_of

from .marching_cubes import marching_cubes, sample_sdf_grid
from .narrow_band import sample_sdf_narrow_band

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class MeshExtractionConfig:
    resolution: int = 256  # SDF samples per side of the [-R, R]^3 grid
    chunk: int = 262_144  # SDF queries per batch
    floater_fraction: float = 0.02  # components with fewer faces than this share of the largest are dropped
    keep_all_significant: bool = True  # keep every component above that share (handles, lids), not only the largest
    face_budget: int | None = 20_000  # decimate to at most this many faces (None: keep all)
    narrow_band_stride: int = 4  # SDF exact only in coarse cells of this many samples near the surface (0: every sample)
    # The surface extracted at SDF = iso_level instead of 0: grown outward by it (field units). export_field
    # sets it for a refined field (silhouette_offset.py), so that the mesh sits where the photos saw it.
    iso_level: float = 0.0


class NoSurfaceError(LirmUserError):
    """The SDF has no zero crossing inside the bounding sphere."""


def field_sdf_grid(field, resolution: int, chunk: int = 262_144, narrow_band_stride: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """The field's SDF on a resolution^3 grid spanning its bounding cube: (values, origin, spacing).
    With a narrow-band stride the values are exact only where marching cubes can find the surface
    (narrow_band.py: the same mesh for several times fewer network queries)."""
    device = device_of(field)

    @torch.no_grad()
    def sdf(points: np.ndarray) -> np.ndarray:
        return field.sdf(torch.from_numpy(points).to(device)[None])[0].float().cpu().numpy()

    if narrow_band_stride > 0:
        band = sample_sdf_narrow_band(sdf, resolution, float(field.radius), chunk, stride=narrow_band_stride)
        values, origin, spacing = band.values, band.origin, band.spacing
    else:
        values, origin, spacing = sample_sdf_grid(sdf, resolution, float(field.radius), chunk)
    if not np.isfinite(values).all():
        raise LirmUserError(f"the field's SDF has {int((~np.isfinite(values)).sum())} NaN or infinite values on the "
                            f"extraction grid; the reconstruction is broken: run the update again or use another checkpoint")
    return values, origin, spacing


def extract_field_mesh(field, config: MeshExtractionConfig = MeshExtractionConfig(), progress: Progress | None = None,
                       timings: dict[str, float] | None = None) -> trimesh.Trimesh:
    """The cleaned, decimated surface; `timings` (if given) receives seconds per stage."""
    timings = {} if timings is None else timings
    clock = time.perf_counter()

    def stage(name: str, message: str, k: int) -> None:
        nonlocal clock
        now = time.perf_counter()
        if name:
            timings[name] = now - clock
        clock = now
        if progress:
            progress(message, k, 3)

    stage("", f"sampling the SDF on a {config.resolution}^3 grid", 0)
    values, origin, spacing = field_sdf_grid(field, config.resolution, config.chunk, config.narrow_band_stride)
    values = values - config.iso_level if config.iso_level else values
    check_has_surface(values)
    stage("sdf_grid", "marching cubes", 1)
    extracted = marching_cubes(values, origin, spacing)
    mesh = trimesh.Trimesh(extracted.vertices, extracted.faces, process=True)
    stage("marching_cubes", f"removing floaters, decimating {len(mesh.faces)} faces to {config.face_budget}", 2)
    mesh = remove_floaters(mesh, config.floater_fraction, config.keep_all_significant)
    if config.face_budget and len(mesh.faces) > config.face_budget:
        mesh = decimate(mesh, config.face_budget)
    stage("decimate", "surface done", 3)
    return mesh


def check_has_surface(values: np.ndarray) -> None:
    if values.min() >= 0:
        raise NoSurfaceError("the field has no surface: its SDF is positive everywhere (empty space); "
                             "nothing to extract. Add views of the object and run another update")
    if values.max() < 0:
        raise NoSurfaceError("the field has no surface: its SDF is negative everywhere (all inside); nothing to "
                             "extract. The reconstruction failed: check the capture's masks and run the update again")


def remove_floaters(mesh: trimesh.Trimesh, fraction: float, keep_all_significant: bool = True) -> trimesh.Trimesh:
    """The largest connected component, plus (if asked) every other one with at least `fraction` of its faces."""
    parts = mesh.split(only_watertight=False)
    if len(parts) <= 1:
        return mesh
    parts = sorted(parts, key=lambda m: len(m.faces), reverse=True)
    biggest = len(parts[0].faces)
    kept = [parts[0]] + ([p for p in parts[1:] if len(p.faces) >= fraction * biggest] if keep_all_significant else [])
    return trimesh.util.concatenate(kept)


def decimate(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """Quadric-error edge collapse (fast-simplification) to about `faces` triangles."""
    if faces < 4:
        raise LirmUserError(f"a face budget of {faces} cannot hold a closed surface; ask for at least a few hundred")
    simplified = mesh.simplify_quadric_decimation(face_count=faces)
    simplified.remove_unreferenced_vertices()
    return simplified

