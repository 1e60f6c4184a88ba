"""A small raw reader of glTF 2.0 files (.gltf with external or data-URI buffers, and .glb).

trimesh turns a glTF into geometry and materials but drops what the renderer needs: material
factors as floats, normal scale, occlusion strength, alpha cutoff, extensions, TANGENT and COLOR_0.
This reader gives the JSON, the buffers and typed accessor arrays so the model loader can take
those from the source. It also validates the container, so that bad files fail here with a message
a user can act on instead of deep inside trimesh.
"""

from __future__ import annotations

import base64
import binascii
import json
import struct
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from lirm.engine.errors import AssetLoadError

_GLB_MAGIC = b"glTF"
_CHUNK_JSON = 0x4E4F534A
_CHUNK_BIN = 0x004E4942

COMPONENT_DTYPES = {
    5120: np.dtype("<i1"),
    5121: np.dtype("<u1"),
    5122: np.dtype("<i2"),
    5123: np.dtype("<u2"),
    5125: np.dtype("<u4"),
    5126: np.dtype("<f4"),
}
TYPE_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


@dataclass
class GltfDocument:
    path: Path
    json: dict
    buffers: list[bytes]

    @property
    def extensions_used(self) -> list[str]:
        return list(self.json.get("extensionsUsed", []))

    @property
    def extensions_required(self) -> list[str]:
        return list(self.json.get("extensionsRequired", []))

    @property
    def image_uris(self) -> list[str | None]:
        """One entry per glTF image: its URI, or None where the image lives in a bufferView."""
        return [img.get("uri") for img in self.json.get("images", [])]

    def image_path(self, index: int) -> Path | None:
        """The file an image refers to, or None when it is embedded (bufferView or data URI)."""
        uri = self.image_uris[index]
        if uri is None or uri.startswith("data:"):
            return None
        return self.path.parent / unquote(uri)

    def missing_images(self) -> dict[int, Path]:
        """Images whose external file does not exist, by image index."""
        missing = {}
        for i in range(len(self.image_uris)):
            p = self.image_path(i)
            if p is not None and not p.is_file():
                missing[i] = p
        return missing

    def accessor(self, index: int, normalize: bool | None = None) -> np.ndarray:
        """Accessor `index` as a (count,) array for SCALAR, else (count, components).

        normalize: None follows the accessor's `normalized` flag; True maps integer components to
        [0, 1] / [-1, 1] anyway (integer COLOR_0 is defined as normalized even where the flag is
        missing). Normalized results are float32.
        """
        accessors = self.json.get("accessors", [])
        if not isinstance(index, int) or not 0 <= index < len(accessors):
            raise self._error(f"refers to accessor {index!r}, but the file has {len(accessors)}")
        acc = accessors[index]
        if "sparse" in acc:
            raise self._error(
                f"accessor {index} is sparse, which is not supported; re-export the model "
                "without sparse accessors (e.g. apply morph targets / shape keys before export)"
            )
        try:
            return self._accessor(index, acc, normalize)
        except (KeyError, IndexError, TypeError, ValueError, OverflowError) as err:
            what = f"{type(err).__name__}: {err}"
            raise self._error(f"accessor {index} is malformed ({what}); export the model again") from None

    def _accessor(self, index: int, acc: dict, normalize: bool | None) -> np.ndarray:
        dtype = COMPONENT_DTYPES[acc["componentType"]]
        width = TYPE_WIDTHS[acc["type"]]
        count = int(acc["count"])
        if count < 0:
            raise ValueError(f"negative count {count}")
        if acc["type"].startswith("MAT") and dtype.itemsize < 4:
            # Columns of byte/short matrices are padded to 4 bytes; nothing we read needs them.
            raise self._error(f"accessor {index}: {acc['type']} with {dtype} components is not supported")
        if "bufferView" not in acc:
            data = np.zeros((count, width), dtype)  # the spec's meaning of a bufferView-less accessor
        else:
            data = self._read_view(index, acc, dtype, width, count)
        if normalize is None:
            normalize = bool(acc.get("normalized", False))
        if normalize and dtype.kind in "iu":
            top = float(np.iinfo(dtype).max)
            data = data.astype(np.float32) / top
            if dtype.kind == "i":
                data = np.maximum(data, -1.0)
        return data.reshape(count) if width == 1 else data

    def _read_view(self, index: int, acc: dict, dtype: np.dtype, width: int, count: int) -> np.ndarray:
        try:
            view = self.json["bufferViews"][acc["bufferView"]]
            buffer = self.buffers[view["buffer"]]
            view_offset = int(view.get("byteOffset", 0))
            view_length = int(view["byteLength"])
        except (KeyError, IndexError, TypeError):
            raise self._error(f"accessor {index} refers to a missing bufferView or buffer") from None
        element = dtype.itemsize * width
        stride = int(view.get("byteStride") or element)
        offset = int(acc.get("byteOffset", 0))
        if stride < element or min(offset, view_offset, view_length) < 0:
            raise ValueError("negative offset or byteStride smaller than one element")
        needed = (count - 1) * stride + element if count > 0 else 0
        if offset + needed > view_length or view_offset + view_length > len(buffer):
            raise self._error(
                f"accessor {index} reads past the end of its buffer; the file is truncated or corrupt, "
                "export it again"
            )
        if count == 0:
            return np.zeros((0, width), dtype)
        raw = np.frombuffer(buffer, np.uint8, count=needed, offset=view_offset + offset)
        rows = np.lib.stride_tricks.as_strided(raw, shape=(count, element), strides=(stride, 1))
        return rows.copy().view(dtype).reshape(count, width)  # an owned, writable array, not a view of the file

    def _error(self, what: str) -> AssetLoadError:
        return AssetLoadError(f"{self.path}: {what}")


def read_gltf(path: str | Path) -> GltfDocument:
    """Parse a .gltf or .glb file and load all its buffers. Raises AssetLoadError for bad input."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as err:
        raise AssetLoadError(f"{path}: cannot be read ({err.strerror or err})") from None
    if path.suffix.lower() == ".glb":
        tree, bin_chunk = _parse_glb(path, data)
    else:
        if data[:4] == _GLB_MAGIC:
            raise AssetLoadError(f"{path}: this is a binary glTF file; rename it to .glb")
        tree, bin_chunk = _parse_json(path, data), None
    _check_structure(path, tree)
    version = str(tree["asset"].get("version", ""))
    if not version.startswith("2."):
        raise AssetLoadError(
            f"{path}: glTF version {version or 'unknown'} is not supported; only glTF 2.0 is "
            "(open and re-export the model with a current tool such as Blender)"
        )
    buffers = [_load_buffer(path, i, spec, bin_chunk) for i, spec in enumerate(tree.get("buffers", []))]
    return GltfDocument(path=path, json=tree, buffers=buffers)


def _parse_glb(path: Path, data: bytes) -> tuple[dict, bytes | None]:
    if data[:4] != _GLB_MAGIC:
        head = data[:64]
        is_text = bool(head) and all(32 <= b < 127 or b in b"\t\r\n" for b in head)
        kind = "it looks like a text file" if is_text else "it does not start with 'glTF'"
        raise AssetLoadError(
            f"{path}: not a binary glTF (.glb) file ({kind}). If it is a text glTF, rename it to "
            ".gltf; otherwise export the model again as .glb"
        )
    if len(data) < 20:
        raise AssetLoadError(f"{path}: the file is truncated ({len(data)} bytes); download or export it again")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise AssetLoadError(f"{path}: GLB version {version} is not supported; re-export it as glTF 2.0")
    if length > len(data):
        raise AssetLoadError(
            f"{path}: the file is truncated ({len(data)} of {length} bytes); download or export it again"
        )
    chunks = []
    offset = 12
    while offset + 8 <= length:
        chunk_length, chunk_type = struct.unpack_from("<II", data, offset)
        end = offset + 8 + chunk_length
        if end > length:
            raise AssetLoadError(
                f"{path}: the file is truncated (a chunk ends at byte {end} of {length}); "
                "download or export it again"
            )
        chunks.append((chunk_type, data[offset + 8 : end]))
        offset = end + (-end % 4)  # chunks are 4-byte aligned
    if not chunks or chunks[0][0] != _CHUNK_JSON:
        raise AssetLoadError(f"{path}: the GLB has no JSON chunk first; the file is corrupt, export it again")
    bin_chunk = next((body for kind, body in chunks[1:] if kind == _CHUNK_BIN), None)
    return _parse_json(path, chunks[0][1]), bin_chunk


def _parse_json(path: Path, text: bytes) -> dict:
    try:
        tree = json.loads(text.decode("utf-8-sig"))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise AssetLoadError(
            f"{path}: the glTF JSON cannot be parsed ({err}); the file is corrupt, export it again"
        ) from None
    if not isinstance(tree, dict) or "asset" not in tree:
        raise AssetLoadError(f"{path}: not a glTF document (no 'asset' entry); export the model again")
    return tree


_ARRAYS = (
    "accessors", "animations", "buffers", "bufferViews", "cameras", "images",
    "materials", "meshes", "nodes", "samplers", "scenes", "skins", "textures",
)  # fmt: skip


def _check_structure(path: Path, tree: dict) -> None:
    """The shapes every reader of the JSON relies on; the rest is checked where it is read."""

    def bad(what: str) -> AssetLoadError:
        return AssetLoadError(
            f"{path}: malformed glTF ({what}); check it with the Khronos glTF validator or export it again"
        )

    if not isinstance(tree.get("asset"), dict):
        raise bad("'asset' is not an object")
    for key in _ARRAYS:
        value = tree.get(key, [])
        if not isinstance(value, list) or not all(isinstance(item, dict) for item in value):
            raise bad(f"'{key}' is not a list of objects")
    for key in ("extensionsUsed", "extensionsRequired"):
        value = tree.get(key, [])
        if not isinstance(value, list) or not all(isinstance(item, str) for item in value):
            raise bad(f"'{key}' is not a list of names")
    for key in ("buffers", "images"):
        if any(not isinstance(item.get("uri", ""), str) for item in tree.get(key, [])):
            raise bad(f"a uri in '{key}' is not a string")
    for mesh in tree.get("meshes", []):
        prims = mesh.get("primitives")
        if not isinstance(prims, list) or not all(
            isinstance(p, dict) and isinstance(p.get("attributes"), dict) for p in prims
        ):
            raise bad(f"mesh '{mesh.get('name', '')}' has malformed primitives")


def _load_buffer(path: Path, index: int, spec: dict, bin_chunk: bytes | None) -> bytes:
    uri = spec.get("uri")
    if uri is None:
        if index != 0 or bin_chunk is None:
            raise AssetLoadError(
                f"{path}: buffer {index} has no data (no uri and no GLB BIN chunk); export the model again"
            )
        data = bin_chunk
    elif uri.startswith("data:"):
        try:
            data = base64.b64decode(uri.split(",", 1)[1], validate=False)
        except (IndexError, binascii.Error):
            raise AssetLoadError(
                f"{path}: buffer {index} has a malformed base64 data URI; export the model again"
            ) from None
    else:
        file = path.parent / unquote(uri)
        if not file.is_file():
            raise AssetLoadError(
                f"{path}: its buffer file '{uri}' was not found at {file}; copy it next to the .gltf "
                "(or export the model as a single .glb)"
            )
        try:
            data = file.read_bytes()
        except OSError as err:
            raise AssetLoadError(f"{path}: buffer file {file} cannot be read ({err.strerror or err})") from None
    expected = spec.get("byteLength", 0)
    if not isinstance(expected, int):
        raise AssetLoadError(f"{path}: buffer {index} has an invalid byteLength; export the model again")
    if len(data) < expected:
        source = f"buffer file '{uri}'" if uri and not uri.startswith("data:") else f"buffer {index}"
        raise AssetLoadError(
            f"{path}: {source} is truncated ({len(data)} of {expected} bytes); download or export it again"
        )
    return data
