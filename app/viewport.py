"""The 3D viewport: an orbit camera driven the way Blender and three.js users expect, and the asset
drawn by the renderer's PBR path (or one of its G-buffer channels) under the current HDRI into a
texture the window shows. Input cameras and suggested shots are drawn over it as frusta.

Mouse: left drag orbits (middle drag too, as in Blender), right drag or shift+drag pans, the wheel
zooms; double-click or F frames the asset. The image is re-rendered only when something changed, so
a still viewport costs nothing even on llvmpipe.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import moderngl
import numpy as np

from lirm.engine.cameras import Camera, orbit_camera
from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import DISPLAY_CHANNELS, Lighting, PBRRenderer, RenderSettings

ORBIT_DEGREES_PER_PIXEL = 0.4
ZOOM_PER_WHEEL_STEP = 0.88
MIN_ELEVATION, MAX_ELEVATION = -89.0, 89.0


@dataclass
class OrbitCamera:
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance: float = 3.0
    azimuth_deg: float = 30.0
    elevation_deg: float = 20.0
    fov_deg: float = 40.0

    def orbit(self, dx: float, dy: float) -> None:
        self.azimuth_deg = (self.azimuth_deg - dx * ORBIT_DEGREES_PER_PIXEL) % 360.0
        self.elevation_deg = float(np.clip(self.elevation_deg + dy * ORBIT_DEGREES_PER_PIXEL, MIN_ELEVATION, MAX_ELEVATION))

    def pan(self, dx: float, dy: float, height_px: int) -> None:
        """Move the target with the cursor: a drag of the image's height moves it by the visible height."""
        camera = self.camera(max(height_px, 1), max(height_px, 1))
        visible = 2.0 * self.distance * math.tan(math.radians(self.fov_deg) / 2.0)
        scale = visible / max(height_px, 1)
        right, down = camera.c2w[:3, 0], camera.c2w[:3, 1]
        self.target = self.target - scale * (dx * right + dy * down)

    def zoom(self, steps: float) -> None:
        self.distance = float(np.clip(self.distance * ZOOM_PER_WHEEL_STEP**steps, 1e-3, 1e4))

    def frame(self, bounds: np.ndarray) -> None:
        """Centre the asset and fit its bounding sphere in the view."""
        self.target = bounds.mean(axis=0)
        radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2.0, 1e-6)
        self.distance = 1.15 * radius / math.sin(math.radians(self.fov_deg) / 2.0)

    def camera(self, width: int, height: int) -> Camera:
        return orbit_camera(self.azimuth_deg, self.elevation_deg, self.distance, width, height, self.fov_deg,
                            target=self.target, axis="y")


class Viewport:
    """Owns the GPU side of the viewport: the uploaded asset, the lighting and the image texture."""

    def __init__(self, ctx: moderngl.Context):
        self.ctx = ctx
        self.renderer = PBRRenderer(ctx)
        self.orbit = OrbitCamera()
        self.scene = None
        self.bounds = np.array([[-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]])
        self.asset_path: Path | None = None
        self.asset_stamp: int | None = None  # the shown file's mtime: a file rewritten in place is shown again
        self._maps = None
        self.environment_key = None
        self.tonemapper = "aces"  # RenderSettings.tonemapper: see set_environment
        self.texture: moderngl.Texture | None = None
        self._fbo: moderngl.Framebuffer | None = None
        self._depth = None
        self.dirty = True
        self.last_render_seconds = 0.0
        self.frame_times: list[float] = []  # seconds per re-render, newest last

    # ---- content -----------------------------------------------------------------------------
    def set_asset(self, path: Path | None, meshes=None, frame: bool = True) -> None:
        """Show the .glb at `path` (or these meshes); None shows nothing."""
        from lirm.engine.assets.model_loader import load_model

        if self.scene is not None:
            self.scene.release()
            self.scene = None
        self.asset_path = path
        self.asset_stamp = path.stat().st_mtime_ns if path is not None and Path(path).is_file() else None
        if meshes is None and path is not None:
            meshes = load_model(path).meshes
        if meshes:
            self.scene = self.renderer.upload(meshes)
            self.bounds = self.scene.bounds
            if frame:
                self.orbit.frame(self.bounds)
        self.dirty = True

    def set_environment(self, environment: Environment, key, tonemapper: str = "aces") -> None:
        """`tonemapper`: "linear" for a capture's own lighting read through plain sRGB, so that the
        asset under it looks as the photos do (camera_response.response_for_capture)."""
        if key == self.environment_key:
            return
        self.tonemapper = tonemapper
        if self._maps is not None:
            self._maps.release()
        self._maps = self.renderer.baker.bake(environment)
        self.environment_key = key
        self.dirty = True

    # ---- drawing -----------------------------------------------------------------------------
    def _target(self, width: int, height: int) -> None:
        if self.texture is not None and self.texture.size == (width, height):
            return
        for obj in (self._fbo, self._depth, self.texture):
            if obj is not None:
                obj.release()
        self.texture = self.ctx.texture((width, height), 3)  # no alpha: the window shows exactly what was drawn
        self._depth = self.ctx.depth_renderbuffer((width, height))
        self._fbo = self.ctx.framebuffer(color_attachments=[self.texture], depth_attachment=self._depth)
        self.dirty = True

    def render(self, width: int, height: int, channel: str, rotation_deg: float, exposure_ev: float, background: bool) -> bool:
        """Re-render into `texture` if anything changed; True when it did."""
        width, height = max(int(width), 16), max(int(height), 16)
        self._target(width, height)
        if not self.dirty:
            return False
        start = time.perf_counter()
        self._fbo.use()
        self._fbo.clear(0.18, 0.18, 0.18, 1.0)
        if self._maps is not None:
            camera = self.orbit.camera(width, height)
            lighting = Lighting(self._maps, rotation_deg, 0.0)
            settings = RenderSettings(exposure_ev=exposure_ev, show_environment=background, supersample=1,
                                      clear_color=(0.18, 0.18, 0.18), tonemapper=self.tonemapper)
            if self.scene is None:
                self.renderer.draw_to_framebuffer(self._fbo, self._empty_scene(), camera, lighting, settings)
            elif channel in DISPLAY_CHANNELS:
                self.renderer.draw_channel_to_framebuffer(self._fbo, self.scene, camera, lighting, channel, settings)
        self.ctx.finish()
        # Give the window its framebuffer back: imgui's backend draws into whatever is bound.
        self.ctx.screen.use()
        self.last_render_seconds = time.perf_counter() - start
        self.frame_times.append(self.last_render_seconds)
        del self.frame_times[:-240]
        self.dirty = False
        return True

    def show_image(self, rgb: np.ndarray, width: int, height: int) -> None:
        """Put a picture made elsewhere (the field preview) into the viewport's texture, scaled to fit."""
        import cv2

        self._target(max(int(width), 16), max(int(height), 16))
        w, h = self.texture.size
        picture = cv2.resize(np.ascontiguousarray(rgb, np.float32), (w, h), interpolation=cv2.INTER_LINEAR)
        data = (np.clip(picture, 0, 1) * 255 + 0.5).astype(np.uint8)[::-1]  # GL rows start at the bottom
        self.texture.write(np.ascontiguousarray(data).tobytes(), alignment=1)
        self.dirty = False

    def _empty_scene(self):
        if not hasattr(self, "_nothing"):
            from lirm.renderer.primitives import uv_sphere

            self._nothing = self.renderer.upload([uv_sphere(1e-4, segments=4)])
        return self._nothing

    def read_image(self) -> np.ndarray:
        """(H, W, 3) uint8 of the last render, top row first (tests and screenshots)."""
        w, h = self.texture.size
        return np.frombuffer(self.texture.read(alignment=1), np.uint8).reshape(h, w, 3)[::-1].copy()

    def project(self, points: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixel positions of world points in the current view, and which are in front of the camera."""
        xy, z = self.orbit.camera(width, height).project(np.asarray(points, np.float64).reshape(-1, 3))
        return xy, z > 1e-6

    def release(self) -> None:
        for obj in (self.scene, getattr(self, "_nothing", None)):
            if obj is not None:
                obj.release()
        if self._maps is not None:
            self._maps.release()
        for obj in (self._fbo, self._depth, self.texture):
            if obj is not None:
                obj.release()
        self.renderer.release()


def frustum_lines(camera: Camera, world_from_capture: np.ndarray, depth: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """Segments of a camera's frustum drawn `depth` (capture units) in front of it, in world space."""
    corners_px = np.array([[0, 0], [camera.width, 0], [camera.width, camera.height], [0, camera.height]], np.float64)
    rays = np.c_[(corners_px[:, 0] - camera.cx) / camera.fx, (corners_px[:, 1] - camera.cy) / camera.fy, np.ones(4)]
    centre = camera.c2w[:3, 3]
    far = centre + depth * rays @ camera.c2w[:3, :3].T
    to_world = lambda p: (np.c_[p, np.ones(len(p))] @ world_from_capture.T)[:, :3]  # noqa: E731
    c, f = to_world(centre[None])[0], to_world(far)
    return [(c, f[i]) for i in range(4)] + [(f[i], f[(i + 1) % 4]) for i in range(4)]
