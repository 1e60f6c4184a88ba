"""Image files written by the engine: 8/16-bit PNG through OpenCV and linear EXR through OpenEXR.

Arrays are RGB(A) with row 0 at the top; conversion to OpenCV's BGR happens here and nowhere else.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .atomic_files import atomic_write, atomic_write_bytes


def encode_png(image: np.ndarray) -> bytes:
    """PNG bytes of uint8 or uint16 (H, W), (H, W, 3) RGB or (H, W, 4) RGBA."""
    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise TypeError(f"PNG needs uint8 or uint16 data, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        image = image[:, :, ::-1]
    elif image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, [2, 1, 0, 3]]
    ok, encoded = cv2.imencode(".png", np.ascontiguousarray(image))
    if not ok:
        raise OSError("could not encode the image as PNG")
    return encoded.tobytes()


def write_png(path: str | Path, image: np.ndarray) -> Path:
    """uint8 or uint16 (H, W), (H, W, 3) RGB or (H, W, 4) RGBA, written atomically."""
    return atomic_write_bytes(path, encode_png(image))


def to_uint8(values: np.ndarray) -> np.ndarray:
    """[0, 1] floats to 8 bits with rounding."""
    return np.clip(np.round(np.asarray(values, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)


def write_exr(path: str | Path, rgb: np.ndarray) -> Path:
    """Linear float32 RGB (H, W, 3) as a ZIP-compressed OpenEXR file."""
    import OpenEXR

    rgb = np.ascontiguousarray(np.asarray(rgb, dtype=np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp: Path) -> None:
        with OpenEXR.File(header, {"RGB": rgb}) as f:
            f.write(str(tmp))

    return atomic_write(path, write)
