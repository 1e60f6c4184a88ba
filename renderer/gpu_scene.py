"""Meshes and their material textures uploaded to one GL context, ready to draw."""

from __future__ import annotations

from dataclasses import dataclass

import moderngl
import numpy as np

from .material import PBRMaterial
from .mesh import MeshData

SRGB8_ALPHA8 = 0x8C43  # GL_SRGB8_ALPHA8: the GPU decodes sRGB to linear before filtering
RGBA8 = 0x8058


@dataclass
class GpuMesh:
    vao: moderngl.VertexArray
    buffers: list[moderngl.Buffer]
    material: PBRMaterial
    textures: dict[str, moderngl.Texture]  # slot -> texture (defaults where the material has none)
    name: str


class GpuScene:
    """A list of MeshData on the GPU plus one object-to-world transform for all of them."""

    def __init__(self, ctx: moderngl.Context, program: moderngl.Program, meshes: list[MeshData], transform: np.ndarray | None = None):
        if not meshes:
            raise ValueError("a scene needs at least one mesh")
        self.ctx = ctx
        self.transform = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
        # Mesa's llvmpipe (22.x) blurs even magnified textures when anisotropic filtering is on
        # (measured: 0.17 albedo error on a magnified 16x16 texture), so only GPUs get it.
        self._anisotropy = 1.0 if "llvmpipe" in ctx.info.get("GL_RENDERER", "") else 8.0
        self._owned_textures: list[moderngl.Texture] = []
        self._texture_cache: dict[tuple[int, str], moderngl.Texture] = {}
        self._defaults = {
            "white_srgb": self._texture(np.full((1, 1, 4), 255, np.uint8), srgb=True, mipmaps=False),
            "white": self._texture(np.full((1, 1, 4), 255, np.uint8), srgb=False, mipmaps=False),
            "flat_normal": self._texture(np.array([[[128, 128, 255, 255]]], np.uint8), srgb=False, mipmaps=False),
        }
        self.meshes = [self._upload(program, m) for m in meshes]
        lo = np.min([m.bounds[0] for m in meshes], axis=0)
        hi = np.max([m.bounds[1] for m in meshes], axis=0)
        self.local_bounds = np.stack([lo, hi])

    @property
    def bounds(self) -> np.ndarray:
        """World-space axis-aligned bounds after the scene transform."""
        lo, hi = self.local_bounds
        corners = np.array([[x, y, z, 1.0] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        world = (corners @ self.transform.T)[:, :3]
        return np.stack([world.min(0), world.max(0)])

    def _upload(self, program: moderngl.Program, mesh: MeshData) -> GpuMesh:
        ctx = self.ctx
        n = len(mesh.positions)
        uvs = mesh.uvs if mesh.uvs is not None else np.zeros((n, 2), np.float32)
        tangents = mesh.tangents if mesh.tangents is not None else np.tile(np.array([[1, 0, 0, 1]], np.float32), (n, 1))
        colors = mesh.colors if mesh.colors is not None else np.ones((n, 4), np.float32)
        attributes = {
            "in_position": mesh.positions,
            "in_normal": mesh.normals,
            "in_uv": uvs,
            "in_tangent": tangents,
            "in_color": colors,
        }
        buffers = []
        content = []
        for name, data in attributes.items():
            if name not in program:  # the compiler drops attributes a shader does not use
                continue
            buf = ctx.buffer(np.ascontiguousarray(data, dtype=np.float32).tobytes())
            buffers.append(buf)
            content.append((buf, f"{data.shape[1]}f", name))
        index_buffer = ctx.buffer(mesh.indices.astype(np.uint32).tobytes())
        buffers.append(index_buffer)
        vao = ctx.vertex_array(program, content, index_buffer=index_buffer, index_element_size=4)
        material = mesh.material
        textures = {
            "base_color_texture": self._material_texture(material, "base_color_texture", "white_srgb"),
            "metallic_roughness_texture": self._material_texture(material, "metallic_roughness_texture", "white"),
            "normal_texture": self._material_texture(material, "normal_texture", "flat_normal"),
            "occlusion_texture": self._material_texture(material, "occlusion_texture", "white"),
            "emissive_texture": self._material_texture(material, "emissive_texture", "white_srgb"),
        }
        return GpuMesh(vao, buffers, material, textures, mesh.name)

    def _material_texture(self, material: PBRMaterial, slot: str, default: str) -> moderngl.Texture:
        image = getattr(material, slot)
        if image is None:
            return self._defaults[default]
        key = (id(image), slot)  # meshes sharing one material share its textures
        if key not in self._texture_cache:
            self._texture_cache[key] = self._texture(_to_rgba(image), srgb=slot in PBRMaterial.SRGB_SLOTS, mipmaps=True)
        return self._texture_cache[key]

    def _texture(self, rgba: np.ndarray, srgb: bool, mipmaps: bool) -> moderngl.Texture:
        h, w = rgba.shape[:2]
        tex = self.ctx.texture((w, h), 4, rgba.tobytes(), internal_format=SRGB8_ALPHA8 if srgb else RGBA8)
        if mipmaps:
            tex.build_mipmaps()
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
            tex.anisotropy = self._anisotropy
        else:
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        self._owned_textures.append(tex)
        return tex

    def release(self) -> None:
        for mesh in self.meshes:
            mesh.vao.release()
            for buf in mesh.buffers:
                buf.release()
        for tex in self._owned_textures:
            tex.release()
        self.meshes = []
        self._owned_textures = []
        self._texture_cache = {}


def _to_rgba(image: np.ndarray) -> np.ndarray:
    h, w, c = image.shape
    if c == 4:
        return np.ascontiguousarray(image)
    rgba = np.full((h, w, 4), 255, np.uint8)
    if c == 1:
        rgba[:, :, :3] = image
    elif c == 2:  # luminance + alpha
        rgba[:, :, :3] = image[:, :, :1]
        rgba[:, :, 3] = image[:, :, 1]
    else:
        rgba[:, :, :3] = image[:, :, :3]
    return rgba
