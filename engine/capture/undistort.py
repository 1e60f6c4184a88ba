"""Undistortion for the model: after posing, views with lens distortion get a pinhole copy.

The network only sees Plücker rays, which could carry distortion, but the renderer, the masks' visual
hull and texture baking all assume pinhole cameras; one undistorted image per view keeps every later
stage simple. The pinhole camera keeps the same intrinsics (fx, fy, cx, cy), so pixels near the
centre do not move and the few at the corners without source data become black (and mask 0).
"""

from __future__ import annotations

import cv2
import numpy as np

from lirm.engine.cameras import Camera


def undistort_image(image: np.ndarray, camera: Camera) -> tuple[np.ndarray, Camera]:
    """(image, camera) -> (pinhole image, pinhole camera) of the same size and intrinsics."""
    if camera.distortion is None:
        return image, camera
    h, w = image.shape[:2]
    pinhole = Camera(width=camera.width, height=camera.height, fx=camera.fx, fy=camera.fy, cx=camera.cx, cy=camera.cy,
                     c2w=camera.c2w, distortion=None)
    # For each pinhole pixel centre, where it lands in the distorted image (both at +0.5 centres).
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    origins, dirs = pinhole.rays_at(np.stack([xs, ys], -1))
    points = origins + dirs  # any point along the ray projects to the same distorted pixel
    src, _ = camera.project(points.reshape(-1, 3))
    map_x = (src[:, 0] - 0.5).reshape(h, w).astype(np.float32)  # OpenCV remap indexes pixel centres at integers
    map_y = (src[:, 1] - 0.5).reshape(h, w).astype(np.float32)
    out = cv2.remap(image, map_x, map_y, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return out, pinhole
