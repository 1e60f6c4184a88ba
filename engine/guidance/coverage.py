"""Which parts of a surface the cameras see well: the coverage half of next-view guidance.

A surface point counts as covered by a camera when it is in the frame, in front of it, not hidden
(its depth agrees with the camera's depth map of the mesh, from the renderer's depth-only pass) and
seen within 60 degrees of its normal: the rule the paper's baseline uses to pick supervised views.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from lirm.engine.cameras import Camera
from lirm.renderer.depth_raster import DepthRasterizer
from lirm.renderer.pbr_renderer import PBRRenderer

COVERAGE_ANGLE_DEG = 60.0


@dataclass(frozen=True)
class CoverageConfig:
    max_angle_deg: float = COVERAGE_ANGLE_DEG
    depth_tolerance: float = 0.02  # relative: |z - depth map| < tol * z counts as visible
    depth_size: int = 96  # depth maps are rendered at this long side


class SurfaceCoverage:
    """The surface (vertices with normals, faces) on the renderer, answering "what does this camera see"."""

    def __init__(self, gl: PBRRenderer | moderngl.Context, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                 config: CoverageConfig = CoverageConfig(), points: np.ndarray | None = None, point_normals: np.ndarray | None = None):
        """The mesh (vertices, faces) hides things; the points tested are its vertices with `normals`, or
        `points` with `point_normals` (e.g. samples spread evenly over a mesh whose vertices are not)."""
        self.points = np.asarray(vertices if points is None else points, np.float64)
        self.normals = np.asarray(normals if points is None else point_normals, np.float64)
        self.config = config
        self.rasterizer = DepthRasterizer(getattr(gl, "ctx", gl))  # a renderer's context, or a context
        self.mesh = self.rasterizer.upload(vertices, faces)

    def depth_map(self, camera: Camera) -> np.ndarray:
        return self.rasterizer.depth(self.mesh, self._small(camera))

    def _small(self, camera: Camera) -> Camera:
        return camera.scaled(self.config.depth_size / max(camera.width, camera.height))

    def seen(self, camera: Camera) -> np.ndarray:
        """(N,) bool: points the camera sees within the angle, in frame and unoccluded."""
        return self.seen_many([camera])[0]

    def seen_many(self, cameras: list[Camera]) -> list[np.ndarray]:
        """seen() for many cameras, their depth maps rendered in one batch."""
        depths = self.rasterizer.depth_many(self.mesh, [self._small(c) for c in cameras])
        return [self._seen_with(camera, depth) for camera, depth in zip(cameras, depths)]

    def _seen_with(self, camera: Camera, depth: np.ndarray) -> np.ndarray:
        xy, z = camera.project(self.points)
        with np.errstate(invalid="ignore"):
            ok = (z > 1e-6) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)
        to_camera = camera.center[None, :] - self.points
        to_camera /= np.maximum(np.linalg.norm(to_camera, axis=1, keepdims=True), 1e-12)
        ok &= np.sum(to_camera * self.normals, axis=1) >= np.cos(np.radians(self.config.max_angle_deg))
        if ok.any():
            h, w = depth.shape
            px = np.clip((xy[ok, 0] * w / camera.width).astype(int), 0, w - 1)
            py = np.clip((xy[ok, 1] * h / camera.height).astype(int), 0, h - 1)
            d = depth[py, px]
            visible = (d > 0) & (np.abs(z[ok] - d) <= self.config.depth_tolerance * z[ok])
            ok[np.nonzero(ok)[0][~visible]] = False
        return ok

    def covered(self, cameras: list[Camera]) -> np.ndarray:
        """(N,) how many of the cameras see each point well."""
        count = np.zeros(len(self.points), np.int32)
        for seen in self.seen_many(cameras):
            count += seen
        return count

    def release(self) -> None:
        self.mesh.release()
        self.rasterizer.release()
