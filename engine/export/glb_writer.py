"""Binary glTF 2.0 (.glb) writing for a textured PBR mesh: one primitive with POSITION, NORMAL,
TANGENT and TEXCOORD_0, a metallic-roughness material (baseColor sRGB, metallicRoughness with G =
roughness and B = metallic, a tangent-space normal map) and the PNGs embedded.

Positions arrive in our world frame (+Z up); glTF is +Y up, so (x, y, z) -> (x, z, -y), the inverse
of what the loader does on import. An optional similarity transform (the capture's normalisation
undone) is applied first, so the asset comes out at its real size and place. The file is written
atomically: an existing file is replaced only by a complete one.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write
from lirm.engine.io.images import encode_png

from .glb_placement import EXTRAS_KEY, UNITS_KEY

Z_UP_TO_Y_UP = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0], [0, -1.0, 0, 0], [0, 0, 0, 1.0]])

ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_INT = 5126, 5125
LINEAR, LINEAR_MIPMAP_LINEAR = 9729, 9987


@dataclass
class TexturedMesh:
    positions: np.ndarray  # (V, 3) world, +Z up
    normals: np.ndarray  # (V, 3)
    tangents: np.ndarray  # (V, 4)
    uvs: np.ndarray  # (V, 2) glTF convention
    faces: np.ndarray  # (F, 3)
    base_color_srgb: np.ndarray  # (S, S, 3) uint8
    metallic_roughness: np.ndarray  # (S, S, 3) uint8: R occlusion/unused, G roughness, B metallic
    normal_map: np.ndarray | None  # (S, S, 3) uint8 tangent space
    name: str = "lirm_asset"


def to_gltf_frame(mesh: TexturedMesh, world_transform: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions, normals and tangents after `world_transform` (a similarity) and the +Z -> +Y-up turn."""
    m = Z_UP_TO_Y_UP @ (np.eye(4) if world_transform is None else np.asarray(world_transform, np.float64))
    linear = m[:3, :3]
    scale = np.cbrt(abs(np.linalg.det(linear)))
    if scale <= 0:
        raise LirmUserError("the export transform is singular; the capture's normalisation is broken")
    rotation = linear / scale
    positions = mesh.positions.astype(np.float64) @ linear.T + m[:3, 3]
    # Vertices of degenerate faces can have zero normals or tangents, which glTF validators refuse:
    # they get +Y, and a tangent perpendicular to their normal.
    normals = _unit(mesh.normals.astype(np.float64) @ rotation.T, np.tile([0.0, 1.0, 0.0], (len(positions), 1)))
    helper = np.where(np.abs(normals[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    tangents = _unit(mesh.tangents[:, :3].astype(np.float64) @ rotation.T, np.cross(normals, helper))
    tangents = np.concatenate([tangents, mesh.tangents[:, 3:]], axis=1)
    return positions.astype(np.float32), normals.astype(np.float32), tangents.astype(np.float32)


def _unit(v: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length; zero rows taken from `fallback` (same shape), made unit too."""
    zero = np.linalg.norm(v, axis=1) < 1e-12
    v = np.where(zero[:, None], fallback, v)
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)


def glb_bytes(mesh: TexturedMesh, world_transform: np.ndarray | None = None, units: str | None = None) -> bytes:
    positions, normals, tangents = to_gltf_frame(mesh, world_transform)
    blob = bytearray()
    views: list[dict] = []

    def add_view(data: bytes, target: int | None = None) -> int:
        while len(blob) % 4:
            blob.append(0)
        view = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        blob.extend(data)
        views.append(view)
        return len(views) - 1

    accessors: list[dict] = []

    def add_accessor(array: np.ndarray, kind: str, component: int, target: int, bounds: bool = False) -> int:
        view = add_view(np.ascontiguousarray(array).tobytes(), target)
        acc = {"bufferView": view, "componentType": component, "count": int(array.shape[0]), "type": kind}
        if bounds:
            acc["min"] = [float(x) for x in array.min(axis=0)]
            acc["max"] = [float(x) for x in array.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    attributes = {
        "POSITION": add_accessor(positions, "VEC3", FLOAT, ARRAY_BUFFER, bounds=True),
        "NORMAL": add_accessor(normals, "VEC3", FLOAT, ARRAY_BUFFER),
        "TEXCOORD_0": add_accessor(mesh.uvs.astype(np.float32), "VEC2", FLOAT, ARRAY_BUFFER),
    }
    if mesh.normal_map is not None:
        attributes["TANGENT"] = add_accessor(tangents, "VEC4", FLOAT, ARRAY_BUFFER)
    indices = add_accessor(mesh.faces.astype(np.uint32).reshape(-1), "SCALAR", UNSIGNED_INT, ELEMENT_ARRAY_BUFFER)

    images = [{"bufferView": add_view(encode_png(mesh.base_color_srgb)), "mimeType": "image/png", "name": "baseColor"},
              {"bufferView": add_view(encode_png(mesh.metallic_roughness)), "mimeType": "image/png", "name": "metallicRoughness"}]
    if mesh.normal_map is not None:
        images.append({"bufferView": add_view(encode_png(mesh.normal_map)), "mimeType": "image/png", "name": "normal"})
    material = {"name": f"{mesh.name}_material",
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 1},
                                         "metallicFactor": 1.0, "roughnessFactor": 1.0}}
    if mesh.normal_map is not None:
        material["normalTexture"] = {"index": 2}
    document = {
        "asset": {"version": "2.0", "generator": "LIRM Studio"},
        "scene": 0,
        # The similarity from the field's frame (the capture's normalised one) to this file's (before
        # the +Z -> +Y turn): lets a viewer draw the capture's cameras where the asset is.
        # And what one unit of the file is ("metres" when the capture has a real size).
        "scenes": [{"nodes": [0], "extras": {EXTRAS_KEY: (
            np.eye(4) if world_transform is None else np.asarray(world_transform, np.float64)).round(9).tolist(),
            **({UNITS_KEY: units} if units else {})}}],
        "nodes": [{"mesh": 0, "name": mesh.name}],
        "meshes": [{"name": mesh.name, "primitives": [{"attributes": attributes, "indices": indices, "material": 0, "mode": 4}]}],
        "materials": [material],
        "samplers": [{"magFilter": LINEAR, "minFilter": LINEAR_MIPMAP_LINEAR}],
        "textures": [{"source": i, "sampler": 0} for i in range(len(images))],
        "images": images,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": 0}],
    }
    while len(blob) % 4:
        blob.append(0)
    document["buffers"][0]["byteLength"] = len(blob)
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
            + struct.pack("<II", len(blob), 0x004E4942) + bytes(blob))


def write_glb(path: str | Path, mesh: TexturedMesh, world_transform: np.ndarray | None = None, units: str | None = None) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".glb":
        raise LirmUserError(f"{path}: the output must be a .glb file")
    data = glb_bytes(mesh, world_transform, units)
    try:
        return atomic_write(path, lambda tmp: tmp.write_bytes(data))
    except OSError as err:
        raise LirmUserError(f"cannot write {path} ({err.strerror}); choose a folder you can write to") from None
