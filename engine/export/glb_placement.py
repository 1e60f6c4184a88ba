"""Where an exported asset was placed: the similarity from the capture's normalised frame to the
file's (before glTF's +Z -> +Y turn), which `glb_writer` records in the scene's extras. A viewer
reads it to draw the capture's cameras and the field where the asset is (the export moves each
asset by its own extent, e.g. to stand on the ground)."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

EXTRAS_KEY = "lirm_world_from_field"
UNITS_KEY = "lirm_units"  # "metres" (the capture has a real size) or "capture units" (arbitrary)


def read_placement(path: str | Path) -> np.ndarray | None:
    """The recorded 4x4, or None for a file without one (another tool's glb, an .obj, a damaged file)."""
    extras = _scene_extras(path)
    try:
        matrix = np.asarray(extras[EXTRAS_KEY], dtype=np.float64)
    except (KeyError, ValueError, TypeError):
        return None
    return matrix if matrix.shape == (4, 4) and np.isfinite(matrix).all() else None


def read_units(path: str | Path) -> str | None:
    """What one unit of the file is, as recorded ("metres", "capture units"), or None."""
    units = _scene_extras(path).get(UNITS_KEY)
    return units if isinstance(units, str) else None


def _scene_extras(path: str | Path) -> dict:
    path = Path(path)
    if path.suffix.lower() != ".glb" or not path.is_file():
        return {}
    try:
        with open(path, "rb") as f:
            header = f.read(20)
            if len(header) < 20 or header[:4] != b"glTF":
                return {}
            length, kind = struct.unpack("<II", header[12:20])
            if kind != 0x4E4F534A:  # "JSON"
                return {}
            gltf = json.loads(f.read(length))
        extras = gltf["scenes"][gltf.get("scene", 0)]["extras"]
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return {}
    return extras if isinstance(extras, dict) else {}
