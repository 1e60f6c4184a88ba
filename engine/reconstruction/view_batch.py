"""Prepared views (capture/crop.py) as the network's ViewBatch, at the model's input size.

The capture caches crops at its own size (256 by default); a model with another input size gets
the images area-resampled and the Plücker map recomputed from the crop camera resized to match, so
every pixel's ray stays exact (interpolating Plücker coordinates would not keep them on rays).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from lirm.engine.capture.crop import PreparedView
from lirm.engine.model.lirm import ViewBatch


def view_batch(views: list[PreparedView], size: int, device: torch.device | str = "cpu") -> ViewBatch:
    """A batch of one scene holding `views`, each resized to size x size."""
    if not views:
        raise ValueError("an update needs at least one prepared view")
    images, backgrounds, pluckers = [], [], []
    for view in views:
        s = view.image_masked.shape[0]
        if s == size:
            images.append(view.image_masked)
            backgrounds.append(view.image_bg)
            pluckers.append(view.plucker)
        else:
            interpolation = cv2.INTER_AREA if s > size else cv2.INTER_LINEAR
            images.append(cv2.resize(view.image_masked, (size, size), interpolation=interpolation))
            backgrounds.append(cv2.resize(view.image_bg, (size, size), interpolation=interpolation))
            pluckers.append(view.camera.resized(size, size).plucker())

    return ViewBatch.from_arrays(np.stack(images), np.stack(backgrounds), np.stack(pluckers), device)
