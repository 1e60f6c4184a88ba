"""Which parts of a surface the cameras see well: the coverage half of next-view guidance.

A surface point counts as covered by a camera when it is in the frame, in front of it, not hidden
(its depth agrees with the camera's depth map of the mesh, rendered by the renderer) and seen within
60 degrees of its normal: the rule the paper's baseline uses to pick supervised views.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.cameras import Camera
from lirm.renderer.environment import Environment
from lirm.renderer.mesh import MeshData
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings

COVERAGE_ANGLE_DEG = 60.0


@dataclass(frozen=True)
class CoverageConfig:
    max_angle_deg: float = COVERAGE_ANGLE_DEG
    depth_tolerance: float = 0.02  # relative: |z - depth map| < tol * z counts as visible
    depth_size: int = 96  # depth maps are rendered at this long side


class SurfaceCoverage:
    """The surface (vertices with normals, faces) on the renderer, answering "what does this camera see"."""

    def __init__(self, renderer: PBRRenderer, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray,
                 config: CoverageConfig = CoverageConfig()):
        self.points = np.asarray(vertices, np.float64)
        self.normals = np.asarray(normals, np.float64)
        self.config = config
        self.renderer = renderer
        mesh = MeshData(np.asarray(vertices, np.float32), np.asarray(faces, np.uint32), normals=np.asarray(normals, np.float32))
        self.scene = renderer.upload([mesh])
        # Depth needs no lighting, but a draw needs some: a tiny constant environment.
        self.lighting = renderer.prepare_lighting(Environment(np.ones((16, 32, 3), np.float32)))

    def depth_map(self, camera: Camera) -> np.ndarray:
        scale = self.config.depth_size / max(camera.width, camera.height)
        small = camera.scaled(scale)
        out = self.renderer.render_view(self.scene, small, self.lighting, RenderSettings(supersample=1))
        return np.where(out.mask > 0.5, out.depth, 0.0).astype(np.float32)

    def seen(self, camera: Camera) -> np.ndarray:
        """(N,) bool: points the camera sees within the angle, in frame and unoccluded."""
        xy, z = camera.project(self.points)
        with np.errstate(invalid="ignore"):
            ok = (z > 1e-6) & (xy[:, 0] >= 0) & (xy[:, 0] < camera.width) & (xy[:, 1] >= 0) & (xy[:, 1] < camera.height)
        to_camera = camera.center[None, :] - self.points
        to_camera /= np.maximum(np.linalg.norm(to_camera, axis=1, keepdims=True), 1e-12)
        ok &= np.sum(to_camera * self.normals, axis=1) >= np.cos(np.radians(self.config.max_angle_deg))
        if ok.any():
            depth = self.depth_map(camera)
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
        for camera in cameras:
            count += self.seen(camera)
        return count

    def release(self) -> None:
        self.scene.release()
        self.lighting.maps.release()
