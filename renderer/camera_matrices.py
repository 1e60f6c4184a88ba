"""OpenGL matrices for OpenCV-convention cameras.

A camera here is anything with `width`, `height`, `fx`, `fy`, `cx`, `cy` (pixels, pixel centres at
+0.5) and `c2w` (4x4 camera-to-world, OpenCV axes: x right, y down, z forward), such as
lirm.engine.cameras.Camera. The projection maps the pixel grid exactly onto the viewport so that a
render read back top row first lines up with the OpenCV image; lens distortion is not rendered.
"""

from __future__ import annotations

import numpy as np

# OpenCV camera axes -> OpenGL camera axes (y up, looking down -z).
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


def view_matrix(c2w: np.ndarray) -> np.ndarray:
    """World -> OpenGL eye space."""
    return OPENCV_TO_OPENGL @ np.linalg.inv(np.asarray(c2w, dtype=np.float64))


def projection_matrix(camera, near: float, far: float) -> np.ndarray:
    """Eye space -> clip space for the camera's pinhole intrinsics (window origin bottom-left)."""
    w, h = float(camera.width), float(camera.height)
    p = np.zeros((4, 4))
    p[0, 0] = 2.0 * camera.fx / w
    p[0, 2] = 1.0 - 2.0 * camera.cx / w
    p[1, 1] = 2.0 * camera.fy / h
    p[1, 2] = 2.0 * camera.cy / h - 1.0
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2.0 * far * near / (far - near)
    p[3, 2] = -1.0
    return p


def view_projection_matrix(camera, near: float, far: float) -> np.ndarray:
    return projection_matrix(camera, near, far) @ view_matrix(camera.c2w)


def near_far_for_bounds(camera, bounds: np.ndarray) -> tuple[float, float]:
    """Depth range that encloses an axis-aligned box, with margin; near stays positive."""
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    c2w = np.asarray(camera.c2w, dtype=np.float64)
    depth = (corners - c2w[:3, 3]) @ c2w[:3, 2]
    radius = 0.5 * float(np.linalg.norm(bounds[1] - bounds[0]))
    far = max(float(depth.max()), 1e-3) * 1.05 + 1e-3
    near = max(float(depth.min()) * 0.95, far * 1e-4, 1e-4)
    if near >= far:
        near = max(far - 2.0 * radius - 1e-3, far * 1e-4)
    return near, far


def gl_bytes(matrix: np.ndarray) -> bytes:
    """Column-major float32 bytes, as GLSL uniforms expect."""
    return np.ascontiguousarray(np.asarray(matrix, dtype=np.float32).T).tobytes()
