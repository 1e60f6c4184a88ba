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
        return [c > 0 for c in self.view_cosines(cameras)]

    def view_cosines(self, cameras: list[Camera]) -> np.ndarray:
        """(C, N) how squarely each camera sees each point: the cosine between the point's normal and
        its direction to the camera where the camera sees it well (at least cos 60° = 0.5), else 0."""
        if not cameras:
            return np.zeros((0, len(self.points)))
        depths = self.rasterizer.depth_many(self.mesh, [self._small(c) for c in cameras])
        seen: list[np.ndarray | None] = [None] * len(cameras)
        # Pinhole cameras of one size (every candidate view) are tested together, the others one by one.
        groups: dict[tuple[int, int], list[int]] = {}
        for i, camera in enumerate(cameras):
            if camera.distortion is None:
                groups.setdefault((int(camera.width), int(camera.height)), []).append(i)
            else:
                seen[i] = self._seen_with(camera, depths[i])
        for members in groups.values():
            for i, row in zip(members, self._seen_pinhole([cameras[i] for i in members], np.stack([depths[i] for i in members]))):
                seen[i] = row
        return np.stack(seen)  # type: ignore[arg-type]

    def _seen_pinhole(self, cameras: list[Camera], depths: np.ndarray) -> np.ndarray:
        """_seen_with for C undistorted cameras of one size at once: (C, N) cosines."""
        w2c = np.stack([np.linalg.inv(c.c2w) for c in cameras])  # (C, 4, 4)
        local = np.matmul(self.points[None], w2c[:, :3, :3].transpose(0, 2, 1)) + w2c[:, None, :3, 3]  # (C, N, 3)
        z = local[..., 2]
        fx, fy, cx, cy = (np.array([getattr(c, k) for c in cameras])[:, None] for k in ("fx", "fy", "cx", "cy"))
        with np.errstate(divide="ignore", invalid="ignore"):
            x = local[..., 0] / z * fx + cx
            y = local[..., 1] / z * fy + cy
        return self._visible(cameras, x, y, z, depths)

    def _seen_with(self, camera: Camera, depth: np.ndarray) -> np.ndarray:
        """One camera of any kind (lens distortion included) against its depth map."""
        xy, z = camera.project(self.points)
        return self._visible([camera], xy[None, :, 0], xy[None, :, 1], z[None], depth[None])[0]

    def _visible(self, cameras: list[Camera], x: np.ndarray, y: np.ndarray, z: np.ndarray, depths: np.ndarray) -> np.ndarray:
        """(C, N) viewing cosines, 0 where not seen, from the points' pixel positions x, y and depths z in
        C cameras of one size: seen means in frame, in front, within the angle and matching the
        camera's depth map."""
        width, height = cameras[0].width, cameras[0].height
        with np.errstate(invalid="ignore"):
            ok = (z > 1e-6) & (x >= 0) & (x < width) & (y >= 0) & (y < height)
        # Within the angle: (center - p) . n >= cos * |center - p|, expanded into matrix products.
        centers = np.stack([c.c2w[:3, 3] for c in cameras])  # (C, 3)
        facing = centers @ self.normals.T - np.sum(self.points * self.normals, axis=1)[None]
        distance = np.sqrt(np.maximum(np.sum(centers**2, axis=1)[:, None] - 2.0 * centers @ self.points.T
                                      + np.sum(self.points**2, axis=1)[None], 0.0))
        cosine = facing / np.maximum(distance, 1e-12)
        ok &= cosine >= np.cos(np.radians(self.config.max_angle_deg))
        c, n = np.nonzero(ok)
        if len(c):
            h, w = depths.shape[1:]
            px = np.clip((x[c, n] * w / width).astype(int), 0, w - 1)
            py = np.clip((y[c, n] * h / height).astype(int), 0, h - 1)
            d = depths[c, py, px]
            zn = z[c, n]
            hidden = ~((d > 0) & (np.abs(zn - d) <= self.config.depth_tolerance * zn))
            ok[c[hidden], n[hidden]] = False
        return np.where(ok, cosine, 0.0)

    def covered(self, cameras: list[Camera]) -> np.ndarray:
        """(N,) how many of the cameras see each point well."""
        return (self.view_cosines(cameras) > 0).sum(axis=0).astype(np.int32)

    def release(self) -> None:
        self.mesh.release()
        self.rasterizer.release()
