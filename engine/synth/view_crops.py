"""Synthetic views made to look like what the capture pipeline hands the network.

`crop_like_capture` cuts every view to the square around its object mask with the capture's margin
and resizes it to the network's input size, with the crop camera from Camera.crop_resize: the same
code path and the same framing as engine/capture/crop.py, so training sees real captures' framing.
`scale_pixels` is the supplementary's on-the-fly pixel perturbation U(0.75, 1.25): a change of
exposure applied to the photo (the object and its surroundings alike).
"""

from __future__ import annotations

import numpy as np

from lirm.engine.capture.crop import CropConfig, EmptyMaskError, crop_box_for_mask, crop_resize_array

from .object_views import ObjectViews


def crop_like_capture(views: ObjectViews, size: int, margin: float = CropConfig().margin) -> ObjectViews:
    """Every view cropped around its mask and resized to size x size; all maps follow the crop.

    A view whose mask is empty keeps its whole frame (resized), as the camera saw it."""
    boxes = []
    for i, camera in enumerate(views.cameras):
        try:
            boxes.append(crop_box_for_mask(views.mask[i], margin))
        except EmptyMaskError:
            boxes.append((0, 0, max(camera.width, camera.height)))
    return crop_views(views, boxes, size)


def resize_views(views: ObjectViews, size: int) -> ObjectViews:
    """Whole (square) views resized to size x size, rays kept."""
    return crop_views(views, [(0, 0, max(c.width, c.height)) for c in views.cameras], size)


def crop_views(views: ObjectViews, boxes: list[tuple[int, int, int]], size: int) -> ObjectViews:
    """View i cut to the square boxes[i] = (x0, y0, side) and resized to size x size."""
    out = {name: [] for name in ("image", "image_bg", "mask", "albedo", "roughness", "metallic", "normal", "depth")}
    cameras = []
    for i, camera in enumerate(views.cameras):
        x0, y0, side = boxes[i]
        cameras.append(camera.crop_resize(x0, y0, side, side, size, size))

        def crop(a: np.ndarray) -> np.ndarray:
            return crop_resize_array(a, x0, y0, side, size)

        mask = np.clip(crop(views.mask[i]), 0.0, 1.0)
        # The object premultiplied by coverage, cropped, then over white: outside the photo the
        # capture's crop is empty (zero coverage), which is white in the masked image.
        premultiplied = views.image[i] - (1.0 - views.mask[i][..., None])
        out["image"].append(np.clip(crop(premultiplied) + (1.0 - mask[..., None]), 0.0, 1.0))
        out["image_bg"].append(np.clip(crop(views.image_bg[i]), 0.0, 1.0))
        out["mask"].append(mask)
        for name in ("albedo", "roughness", "metallic", "normal", "depth"):
            value = getattr(views, name)
            if value is not None:
                out[name].append(crop(value[i]))
    stacked = {k: (np.stack(v).astype(np.float32) if v else None) for k, v in out.items()}
    return ObjectViews(cameras, **stacked)


def scale_pixels(views: ObjectViews, scale: float) -> ObjectViews:
    """The photos scaled by `scale` and clipped (materials untouched): images over white stay over white."""
    mask = views.mask[..., None]
    premultiplied = np.minimum((views.image - (1.0 - mask)) * scale, mask)
    image = np.clip(premultiplied, 0.0, 1.0) + (1.0 - mask)
    return ObjectViews(views.cameras, np.clip(image, 0, 1).astype(np.float32),
                       np.clip(views.image_bg * scale, 0, 1).astype(np.float32), views.mask, views.albedo,
                       views.roughness, views.metallic, views.normal, views.depth)
