"""Baking the field's materials into the mesh's UV atlas.

Every covered texel of the atlas (renderer/uv_raster.py) is a point on the extracted mesh; it is
moved onto the field's zero level set along the SDF gradient (the decimated mesh lies a little off
it), and the field is queried there: albedo, roughness, metallic and the field's normal. The normal
is stored in tangent space against the mesh's own interpolated frame (the renderer's and glTF's
convention: green toward the top of the image), so the normal map restores the detail the
decimated mesh lost. Uncovered texels are filled from their neighbours (dilation) so that bilinear
filtering and mip-maps never pull the empty gutter colour across a seam.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
import torch

from lirm.engine.io.images import to_uint8
from lirm.engine.model.field import device_of
from lirm.engine.model.volume_renderer import numerical_normals
from lirm.renderer.tonemap import linear_to_srgb
from lirm.renderer.uv_raster import UVRaster

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class BakeConfig:
    chunk: int = 131_072  # texels per field query
    projection_steps: int = 2  # Newton steps onto the zero level set (0: query on the mesh itself)
    dilation: int = 16  # texels grown into the gutters before the rest is filled with the mean
    # Which normal the normal map stores: "sdf", the SDF's own gradient (the geometry the mesh was
    # cut from, at the field's full detail), or "head", the field's predicted shading normal. On a
    # refined demo capture the head's normal was 29 degrees (median) off the geometry, 13% of the
    # texels over 60 degrees, which made a lumpy relit asset; the gradient is the honest detail.
    normal_source: str = "sdf"


@dataclass
class BakedTextures:
    base_color: np.ndarray  # (S, S, 3) linear
    roughness: np.ndarray  # (S, S)
    metallic: np.ndarray  # (S, S)
    normal: np.ndarray  # (S, S, 3) tangent-space unit normal
    covered: np.ndarray  # (S, S) bool: texels the mesh covers

    def base_color_srgb8(self) -> np.ndarray:
        return to_uint8(linear_to_srgb(np.clip(self.base_color, 0.0, 1.0)))

    def metallic_roughness8(self) -> np.ndarray:
        """glTF's metallicRoughness texture: R unused (occlusion slot, white), G roughness, B metallic, all linear."""
        s = self.roughness.shape[0]
        return np.stack([np.full((s, s), 255, np.uint8), to_uint8(self.roughness), to_uint8(self.metallic)], axis=-1)

    def normal8(self) -> np.ndarray:
        return to_uint8(self.normal * 0.5 + 0.5)





@torch.no_grad()
def query_surface(field, points: np.ndarray, config: BakeConfig = BakeConfig()) -> dict[str, np.ndarray]:
    """The field's materials and normal at the surface points nearest to `points` (N, 3)."""
    device = device_of(field)
    out = {"albedo": [], "roughness": [], "metallic": [], "normal": []}
    for start in range(0, len(points), config.chunk):
        p = torch.from_numpy(np.ascontiguousarray(points[start:start + config.chunk], np.float32)).to(device)
        for _ in range(config.projection_steps):
            s = field.sdf(p[None])[0]
            p = p - s[:, None] * numerical_normals(field, p)
        sample = field.sample(p[None], None)
        out["albedo"].append(sample.albedo[0].float().cpu().numpy())
        out["roughness"].append(sample.roughness[0].float().cpu().numpy())
        out["metallic"].append(sample.metallic[0].float().cpu().numpy())
        normal = numerical_normals(field, p) if config.normal_source == "sdf" else sample.normal[0]
        out["normal"].append(normal.float().cpu().numpy())
    return {k: np.concatenate(v) if v else np.zeros((0,)) for k, v in out.items()}


def bake_textures(field, raster: UVRaster, config: BakeConfig = BakeConfig(), progress: Progress | None = None) -> BakedTextures:
    s = raster.covered.shape[0]
    idx = np.nonzero(raster.covered.reshape(-1))[0]
    if progress:
        progress(f"querying the field at {len(idx)} texels", 0, 2)
    values = query_surface(field, raster.position.reshape(-1, 3)[idx], config)
    # Tangent space against the mesh's interpolated frame, as the shader rebuilds it.
    n = values["normal"]
    n_mesh = raster.normal.reshape(-1, 3)[idx]
    t = raster.tangent.reshape(-1, 4)[idx]
    # Texels where the mesh's interpolated frame is degenerate (zero-length normals from the
    # decimator) take the field's normal and a flat normal-map texel.
    broken = ~np.isfinite(n_mesh).all(axis=1) | ~np.isfinite(t).all(axis=1)
    n_mesh = np.where(broken[:, None], n, n_mesh)
    t = np.where(broken[:, None], np.array([1.0, 0.0, 0.0, 1.0], np.float32), t)
    n_mesh /= np.maximum(np.linalg.norm(n_mesh, axis=1, keepdims=True), 1e-12)
    tangent = t[:, :3] - n_mesh * np.sum(n_mesh * t[:, :3], axis=1, keepdims=True)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-12)
    bitangent = np.cross(n_mesh, tangent) * np.where(t[:, 3:] < 0.0, -1.0, 1.0)
    local = np.stack([np.sum(n * tangent, 1), np.sum(n * bitangent, 1), np.sum(n * n_mesh, 1)], axis=1)
    local[:, 2] = np.maximum(local[:, 2], 0.05)  # a normal map cannot face away from its surface
    local /= np.linalg.norm(local, axis=1, keepdims=True)
    local[broken | ~np.isfinite(local).all(axis=1)] = (0.0, 0.0, 1.0)
    if progress:
        progress("filling the gutters", 1, 2)

    def image(flat: np.ndarray, channels: int, empty: float) -> np.ndarray:
        a = np.full((s * s, channels), empty, np.float32)
        a[idx] = flat.reshape(len(idx), channels)
        return dilate(a.reshape(s, s, channels), raster.covered, config.dilation)

    normal = image(local, 3, 0.0)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    return BakedTextures(image(values["albedo"], 3, 0.0), image(values["roughness"], 1, 0.0)[..., 0],
                         image(values["metallic"], 1, 0.0)[..., 0], normal, raster.covered.copy())


def dilate(values: np.ndarray, covered: np.ndarray, iterations: int) -> np.ndarray:
    """Grow covered texels' values into uncovered ones, one ring per iteration (mean of covered
    neighbours); what is still empty afterwards gets the mean of all covered texels."""
    v = values.astype(np.float32).copy()
    known = covered.astype(np.float32)
    for _ in range(iterations):
        if known.min() > 0:
            break
        weight = cv2.boxFilter(known, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        total = cv2.boxFilter(v * known[..., None], -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        total = total.reshape(v.shape)
        grow = (known == 0) & (weight > 0)
        v[grow] = total[grow] / weight[grow][:, None]
        known = np.where(grow, 1.0, known).astype(np.float32)
    if known.min() == 0 and covered.any():
        v[known == 0] = v[covered].mean(axis=0)
    return v
