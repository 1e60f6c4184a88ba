"""A depth-only rasteriser: camera-space z maps of one mesh from many cameras, for visibility tests.

Next-view guidance tests hundreds of candidate views after every update; the full PBR path (G-buffer,
image-based lighting, tone mapping, read-back of five targets) costs three draws and 20 floats a
pixel for the one number it needs. This pass draws the mesh once per camera into a single float
target with a depth buffer and reads that back.

Depth maps come back top row first (OpenCV image order), 0 where no surface is seen.
"""

from __future__ import annotations

import moderngl
import numpy as np

from .camera_matrices import gl_bytes, near_far_for_bounds, view_projection_matrix
from .context import make_current
from .shader_source import shader_source


GL_CLIP_DISTANCE0 = 0x3000  # moderngl has no flag for user clip planes; glEnable takes them directly


def gl_enable_clip_distance(ctx: moderngl.Context, plane: int, on: bool) -> None:
    (ctx.enable_direct if on else ctx.disable_direct)(GL_CLIP_DISTANCE0 + plane)


class DepthMesh:
    """A mesh uploaded for depth rendering; release() when done."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, vertices: np.ndarray, faces: np.ndarray):
        vertices = np.ascontiguousarray(vertices, np.float32)
        faces = np.ascontiguousarray(faces, np.uint32)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"expected (N, 3) vertices and (F, 3) faces, got {vertices.shape} and {faces.shape}")
        self.bounds = np.stack([vertices.min(0), vertices.max(0)]).astype(np.float64) if len(vertices) else np.zeros((2, 3))
        drawable = len(vertices) > 0 and len(faces) > 0  # GL refuses empty buffers; nothing to draw anyway
        self.vbo = ctx.buffer(vertices.tobytes()) if drawable else None
        self.ibo = ctx.buffer(faces.tobytes()) if drawable else None
        self.vao = (ctx.vertex_array(program, [(self.vbo, "3f", "in_position")], index_buffer=self.ibo, index_element_size=4)
                    if drawable else None)

    def release(self) -> None:
        for obj in (self.vao, self.ibo, self.vbo):
            if obj is not None:
                obj.release()


class DepthRasterizer:
    def __init__(self, ctx: moderngl.Context):
        make_current(ctx)
        self.ctx = ctx
        self.program = ctx.program(vertex_shader=shader_source("depth_raster.vert"),
                                   fragment_shader=shader_source("depth_raster.frag"))
        self._targets: dict[tuple[int, int], tuple] = {}

    def upload(self, vertices: np.ndarray, faces: np.ndarray) -> DepthMesh:
        make_current(self.ctx)
        return DepthMesh(self.ctx, self.program, vertices, faces)

    def _target(self, width: int, height: int):
        key = (width, height)
        if key not in self._targets:
            colour = self.ctx.texture(key, 1, dtype="f4")
            depth = self.ctx.depth_renderbuffer(key)
            self._targets[key] = (colour, depth, self.ctx.framebuffer(color_attachments=[colour], depth_attachment=depth))
        return self._targets[key][2]

    def depth(self, mesh: DepthMesh, camera) -> np.ndarray:
        """(H, W) float32 camera-space z of the nearest surface, 0 where there is none; H, W = the camera's size."""
        return self.depth_many(mesh, [camera])[0]

    def depth_many(self, mesh: DepthMesh, cameras: list, columns: int = 16) -> list[np.ndarray]:
        """The depth maps of many cameras of one size, drawn as tiles of one target and read back once:
        on llvmpipe each read-back waits for the rasteriser, so one read for all is several times faster."""
        if not cameras:
            return []
        w, h = int(cameras[0].width), int(cameras[0].height)
        if any((int(c.width), int(c.height)) != (w, h) for c in cameras):
            return [self.depth_many(mesh, [c])[0] for c in cameras]
        make_current(self.ctx)
        columns = min(columns, len(cameras))
        rows = -(-len(cameras) // columns)
        fbo = self._target(w * columns, h * rows)
        fbo.use()
        fbo.viewport = (0, 0, w * columns, h * rows)
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if mesh.vao is not None:
            matrices, eyes = [], []
            for camera in cameras:
                near, far = near_far_for_bounds(camera, mesh.bounds)
                c2w = np.asarray(camera.c2w, dtype=np.float64)
                matrices.append(gl_bytes(view_projection_matrix(camera, near, far)))
                eyes.append(np.array([*c2w[:3, 3], 1.0, *c2w[:3, 2], 0.0], np.float32).tobytes())
            camera_buffer = self.ctx.buffer(b"".join(matrices))
            eye_buffer = self.ctx.buffer(b"".join(eyes))
            try:
                camera_buffer.bind_to_storage_buffer(0)
                eye_buffer.bind_to_storage_buffer(1)
                self.program["u_columns"].value = columns
                self.program["u_rows"].value = rows
                self.ctx.enable(moderngl.DEPTH_TEST)
                self.ctx.disable(moderngl.CULL_FACE | moderngl.BLEND)
                for plane in range(4):
                    gl_enable_clip_distance(self.ctx, plane, True)
                mesh.vao.render(moderngl.TRIANGLES, instances=len(cameras))
            finally:
                for plane in range(4):
                    gl_enable_clip_distance(self.ctx, plane, False)
                camera_buffer.release()
                eye_buffer.release()
        data = np.frombuffer(fbo.read(components=1, dtype="f4"), np.float32).reshape(h * rows, w * columns)[::-1]  # GL rows start at the bottom
        return [data[(i // columns) * h:(i // columns + 1) * h, (i % columns) * w:(i % columns + 1) * w].copy()
                for i in range(len(cameras))]

    def release(self) -> None:
        for colour, depth, fbo in self._targets.values():
            for obj in (fbo, depth, colour):
                obj.release()
        self._targets.clear()
        self.program.release()
