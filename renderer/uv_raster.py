"""Rasterisation in texture space, for baking: per texel of a UV atlas, the surface point, normal and
tangent that the texel shows. Texel centres are sampled exactly (no multisampling), so a texel
holds the surface at its own centre; texels no triangle covers are reported as uncovered.

Arrays come back with row 0 = the image's top row = v near 0, glTF's texture convention.
"""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from .context import make_current
from .shader_source import shader_source


@dataclass
class UVRaster:
    position: np.ndarray  # (S, S, 3) float32 world position
    normal: np.ndarray  # (S, S, 3) float32 unit interpolated vertex normal
    tangent: np.ndarray  # (S, S, 4) float32 unit tangent, w = bitangent sign
    covered: np.ndarray  # (S, S) bool


class UVRasterizer:
    def __init__(self, ctx: moderngl.Context):
        make_current(ctx)
        self.ctx = ctx
        self.program = ctx.program(vertex_shader=shader_source("uv_raster.vert"), fragment_shader=shader_source("uv_raster.frag"))

    def rasterize(self, positions: np.ndarray, normals: np.ndarray, tangents: np.ndarray, uvs: np.ndarray,
                  faces: np.ndarray, size: int) -> UVRaster:
        make_current(self.ctx)
        ctx = self.ctx
        n = len(positions)
        for name, a, width in (("normals", normals, 3), ("tangents", tangents, 4), ("uvs", uvs, 2)):
            if a.shape != (n, width):
                raise ValueError(f"{name} has shape {a.shape}, expected ({n}, {width})")
        buffers = [ctx.buffer(np.ascontiguousarray(a, np.float32).tobytes()) for a in (uvs, positions, normals, tangents)]
        index = ctx.buffer(np.ascontiguousarray(faces, np.uint32).tobytes())
        vao = ctx.vertex_array(self.program, [(buffers[0], "2f", "in_uv"), (buffers[1], "3f", "in_position"),
                                              (buffers[2], "3f", "in_normal"), (buffers[3], "4f", "in_tangent")],
                               index_buffer=index, index_element_size=4)
        targets = [ctx.texture((size, size), 4, dtype="f4") for _ in range(3)]
        fbo = ctx.framebuffer(color_attachments=targets)
        try:
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
            vao.render(moderngl.TRIANGLES)
            # GL's first row is the bottom one, where v = 0 was drawn (clip y = 2v - 1): reading it
            # first gives row 0 = v near 0, the top of a glTF texture.
            out = [np.frombuffer(t.read(), np.float32).reshape(size, size, 4).copy() for t in targets]
        finally:
            for obj in [fbo, vao, index, *targets, *buffers]:
                obj.release()
        covered = out[0][..., 3] > 0.5
        return UVRaster(out[0][..., :3], out[1][..., :3], out[2], covered)

    def release(self) -> None:
        self.program.release()
