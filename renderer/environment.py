"""An HDR environment as numpy data: linear radiance on an equirectangular grid.

Direction convention (world +Z up, the same as Blender's world texture): the image centre looks
along +X, the top row is the zenith (+Z), and moving right in the image turns clockwise seen from
above (toward -Y), so the panorama reads unmirrored from inside. `direction_to_equirect_uv` is the
one definition; the GLSL in shaders/common.glsl mirrors it and a test holds them together.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Environment:
    radiance: np.ndarray  # (H, W, 3) float32 linear RGB, row 0 = zenith
    name: str = "environment"

    def __post_init__(self) -> None:
        r = np.asarray(self.radiance, dtype=np.float32)
        if r.ndim != 3 or r.shape[2] != 3:
            raise ValueError(f"environment {self.name!r}: radiance must be (H, W, 3), got {r.shape}")
        if r.shape[0] < 2 or r.shape[1] < 4:
            raise ValueError(f"environment {self.name!r}: {r.shape[1]}x{r.shape[0]} is too small")
        if not np.isfinite(r).all() or (r < 0).any():
            raise ValueError(f"environment {self.name!r}: radiance must be finite and non-negative")
        self.radiance = np.ascontiguousarray(r)

    @property
    def height(self) -> int:
        return self.radiance.shape[0]

    @property
    def width(self) -> int:
        return self.radiance.shape[1]

    def lookup(self, directions: np.ndarray) -> np.ndarray:
        """Bilinear radiance lookup for world directions (..., 3); wraps in longitude."""
        u, v = direction_to_equirect_uv(directions)
        h, w = self.height, self.width
        x = u * w - 0.5
        y = np.clip(v * h - 0.5, 0.0, h - 1.0)
        x0 = np.floor(x).astype(np.int64)
        y0 = np.floor(y).astype(np.int64)
        fx = (x - x0)[..., None]
        fy = (y - y0)[..., None]
        y1 = np.minimum(y0 + 1, h - 1)
        x0w, x1w = x0 % w, (x0 + 1) % w
        r = self.radiance
        top = r[y0, x0w] * (1 - fx) + r[y0, x1w] * fx
        bottom = r[y1, x0w] * (1 - fx) + r[y1, x1w] * fx
        return top * (1 - fy) + bottom * fy

    def texel_directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit direction (H, W, 3) and solid angle (H, W) of every texel centre."""
        h, w = self.height, self.width
        u = (np.arange(w) + 0.5) / w
        v = (np.arange(h) + 0.5) / h
        uu, vv = np.meshgrid(u, v)
        dirs = equirect_uv_to_direction(uu, vv)
        theta_edges = np.linspace(0.0, np.pi, h + 1)
        band = (np.cos(theta_edges[:-1]) - np.cos(theta_edges[1:])) * (2.0 * np.pi / w)
        return dirs, np.repeat(band[:, None], w, axis=1)


def direction_to_equirect_uv(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.asarray(directions, dtype=np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    u = 0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2.0 * np.pi)
    v = np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / np.pi
    return u % 1.0, v


def equirect_uv_to_direction(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    phi = (0.5 - np.asarray(u, dtype=np.float64)) * 2.0 * np.pi
    theta = np.asarray(v, dtype=np.float64) * np.pi
    s = np.sin(theta)
    return np.stack([s * np.cos(phi), s * np.sin(phi), np.cos(theta)], axis=-1)


def rotation_about_z(degrees: float) -> np.ndarray:
    """3x3 rotation of the environment about +Z (positive = counter-clockwise seen from above)."""
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
