"""Square crops around the object that keep every pixel's ray (the paper's Stanford-ORB recipe).

The crop camera comes from the full-image camera by `Camera.crop_resize`, so the Plücker map of the
crop holds exactly the rays those pixels had in the full photo: a small object in a big photo fills
the network's input without losing where it is.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lirm.engine.cameras import Camera


@dataclass(frozen=True)
class CropConfig:
    size: int = 256  # the model's input resolution
    margin: float = 0.1  # extra space around the mask's bounding box, per side, as a fraction of its size
    background_value: float = 1.0  # what the masked image shows outside the object (white)


@dataclass
class PreparedView:
    """One view as the network sees it (all float32, display-referred sRGB in [0, 1] for images)."""

    frame_id: str
    image_masked: np.ndarray  # (S, S, 3) object on the background value
    image_bg: np.ndarray  # (S, S, 3) the same crop unmasked: the surroundings tell the lighting
    mask: np.ndarray  # (S, S) in [0, 1]
    plucker: np.ndarray  # (S, S, 6) (d, o x d) of the full-image rays at these pixels
    camera: Camera  # the crop's camera
    crop_box: tuple[int, int, int]  # x0, y0, side in working-image pixels (may reach outside the image)


class EmptyMaskError(ValueError):
    """The view's mask has no object pixels."""


def crop_box_for_mask(mask: np.ndarray, margin: float) -> tuple[int, int, int]:
    ys, xs = np.nonzero(mask > 127 if mask.dtype == np.uint8 else mask > 0.5)
    if len(xs) == 0:
        raise EmptyMaskError("the mask is empty")
    x_lo, x_hi, y_lo, y_hi = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
    side = int(np.ceil(max(x_hi - x_lo, y_hi - y_lo) * (1.0 + 2.0 * margin)))
    side = max(side, 8)
    x0 = int(np.floor((x_lo + x_hi - side) / 2.0))
    y0 = int(np.floor((y_lo + y_hi - side) / 2.0))
    return x0, y0, side


def prepare_view(frame_id: str, image: np.ndarray, mask: np.ndarray, camera: Camera, config: CropConfig = CropConfig()) -> PreparedView:
    """image: (H, W, 3) uint8 RGB working image; mask: (H, W) uint8; camera: its full-image camera."""
    h, w = image.shape[:2]
    if mask.shape != (h, w) or (camera.width, camera.height) != (w, h):
        raise ValueError(f"view {frame_id}: image {w}x{h}, mask {mask.shape[::-1]} and camera "
                         f"{camera.width}x{camera.height} must agree")
    x0, y0, side = crop_box_for_mask(mask, config.margin)
    s = config.size
    rgb = crop_resize_array(image.astype(np.float32) / 255.0, x0, y0, side, s)
    alpha = crop_resize_array(mask.astype(np.float32) / 255.0, x0, y0, side, s)
    crop_camera = camera.crop_resize(x0, y0, side, side, s, s)
    masked = rgb * alpha[..., None] + config.background_value * (1.0 - alpha[..., None])
    return PreparedView(frame_id, masked.astype(np.float32), rgb.astype(np.float32), alpha.astype(np.float32),
                        crop_camera.plucker(), crop_camera, (x0, y0, side))


def crop_resize_array(a: np.ndarray, x0: int, y0: int, side: int, out: int) -> np.ndarray:
    """The square [x0, x0+side) x [y0, y0+side), zero outside the image, area-resampled to out x out.
    Output pixel i covers input [x0 + i*side/out, x0 + (i+1)*side/out): Camera.crop_resize's mapping."""
    h, w = a.shape[:2]
    pad = ((max(0, -y0), max(0, y0 + side - h)), (max(0, -x0), max(0, x0 + side - w))) + ((0, 0),) * (a.ndim - 2)
    padded = np.pad(a, pad)
    region = padded[y0 + pad[0][0]: y0 + pad[0][0] + side, x0 + pad[1][0]: x0 + pad[1][0] + side]
    interpolation = cv2.INTER_AREA if side > out else cv2.INTER_LINEAR
    return cv2.resize(region, (out, out), interpolation=interpolation)
