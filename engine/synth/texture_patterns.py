"""2-D texture patterns and a material canvas for procedural objects (numpy + OpenCV, no GL).

Base colours are authored as display-referred sRGB in [0, 1], the encoding glTF stores them in;
roughness, metallic and height are linear. Height is in the object's length units so that normal
maps come out with physical slopes. Normal maps follow glTF: tangent space, +Y (green) toward the
top of the image, where texture row 0 is v = 0.
"""

from __future__ import annotations

import colorsys

import cv2
import numpy as np

from lirm.renderer.material import PBRMaterial


def srgb(hex_or_rgb: str | tuple[float, float, float]) -> np.ndarray:
    if isinstance(hex_or_rgb, str):
        h = hex_or_rgb.lstrip("#")
        return np.array([int(h[k : k + 2], 16) / 255.0 for k in (0, 2, 4)], dtype=np.float32)
    return np.asarray(hex_or_rgb, dtype=np.float32)


def jitter_color(
    color, rng: np.random.Generator, hue: float = 0.03, sat: float = 0.08, val: float = 0.06
) -> np.ndarray:
    """A nearby colour: small random shifts in hue, saturation and value."""
    hh, ss, vv = colorsys.rgb_to_hsv(*[float(c) for c in srgb(color)])
    hh = (hh + rng.uniform(-hue, hue)) % 1.0
    ss = float(np.clip(ss + rng.uniform(-sat, sat), 0.0, 1.0))
    vv = float(np.clip(vv + rng.uniform(-val, val), 0.02, 0.98))
    return np.array(colorsys.hsv_to_rgb(hh, ss, vv), dtype=np.float32)


def smoothstep(e0: float, e1: float, x):
    t = np.clip((np.asarray(x, dtype=np.float32) - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def box(x, lo: float, hi: float, soft: float = 1e-3):
    """1 on [lo, hi], 0 outside, with smooth edges `soft` wide (anti-aliasing)."""
    return smoothstep(lo - soft, lo + soft, x) * (1.0 - smoothstep(hi - soft, hi + soft, x))


def square_wave(x, duty: float = 0.5, soft: float = 0.02):
    """Period-1 wave: 1 on [0, duty) of each period, 0 elsewhere, smooth edges."""
    f = np.mod(np.asarray(x, dtype=np.float32), 1.0)
    return box(f, 0.0, duty, soft) + box(f, 1.0, 1.0 + duty, soft)


def triangle_wave(x):
    """Period-1 wave rising 0 -> 1 -> 0."""
    f = np.mod(np.asarray(x, dtype=np.float32), 1.0)
    return 1.0 - np.abs(2.0 * f - 1.0)


def checker(u, v, nu: int, nv: int) -> np.ndarray:
    return (np.floor(np.asarray(u) * nu) + np.floor(np.asarray(v) * nv)).astype(np.int64) % 2


def value_noise(
    rng: np.random.Generator,
    height: int,
    width: int,
    cells: tuple[int, int] = (4, 4),
    octaves: int = 3,
    gain: float = 0.5,
) -> np.ndarray:
    """Smooth value noise in [0, 1], periodic in both directions (seamless on a lathe's u seam).

    `cells` is the (rows, columns) lattice of the first octave; each octave doubles it. Use powers
    of two that divide the size, so that the period is exact.
    """
    total = np.zeros((height, width), dtype=np.float32)
    cy, cx = cells
    amp, norm = 1.0, 0.0
    for _ in range(octaves):
        cy, cx = min(cy, height), min(cx, width)
        grid = np.pad(rng.random((cy, cx), dtype=np.float32), 2, mode="wrap")
        sy, sx = height / cy, width / cx
        big = cv2.resize(grid, (int(round((cx + 4) * sx)), int(round((cy + 4) * sy))), interpolation=cv2.INTER_CUBIC)
        oy, ox = int(round(2 * sy)), int(round(2 * sx))
        total += amp * big[oy : oy + height, ox : ox + width]
        norm += amp
        amp *= gain
        cy, cx = cy * 2, cx * 2
    return np.clip(total / norm, 0.0, 1.0)


def streaks(rng: np.random.Generator, height: int, width: int, along_rows: bool = True) -> np.ndarray:
    """Brushed-metal streaks in [0, 1]: fine variation across, long runs along rows (or columns)."""
    if along_rows:
        n = value_noise(rng, height, width, cells=(height // 2, 4), octaves=2)
    else:
        n = value_noise(rng, height, width, cells=(4, width // 2), octaves=2)
    return np.clip((n - 0.5) * 2.5 + 0.5, 0.0, 1.0)


def text_mask(
    text: str,
    width: int,
    height: int,
    font: int = cv2.FONT_HERSHEY_DUPLEX,
    weight: float = 0.1,
    margin: float = 0.06,
) -> np.ndarray:
    """Anti-aliased ink coverage (height, width) float32 of `text`, centred and fitted to the box.

    `weight` is the stroke width relative to the glyph height. Rendered large and shrunk so the
    edges are smooth at any size.
    """
    scale = 4.0
    thick = max(1, int(round(weight * 22 * scale)))
    (tw, th), base = cv2.getTextSize(text, font, scale, thick)
    canvas = np.zeros((th + base + 4 * thick, tw + 4 * thick), dtype=np.uint8)
    cv2.putText(canvas, text, (2 * thick, th + 2 * thick), font, scale, 255, thick, cv2.LINE_AA)
    ys, xs = np.nonzero(canvas)
    out = np.zeros((height, width), dtype=np.float32)
    if len(ys) == 0:
        return out
    crop = canvas[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1]
    ch, cw = crop.shape
    s = min(width * (1 - 2 * margin) / cw, height * (1 - 2 * margin) / ch)
    nw, nh = max(1, int(round(cw * s))), max(1, int(round(ch * s)))
    small = cv2.resize(crop, (nw, nh), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    y0, x0 = (height - nh) // 2, (width - nw) // 2
    out[y0 : y0 + nh, x0 : x0 + nw] = small
    return out


def rounded_rect(x, y, half_w: float, half_h: float, radius: float, soft: float):
    """Coverage of a rounded rectangle centred at the origin of coordinates (x, y)."""
    qx = np.abs(x) - (half_w - radius)
    qy = np.abs(y) - (half_h - radius)
    d = np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)) + np.minimum(np.maximum(qx, qy), 0) - radius
    return 1.0 - smoothstep(-soft, soft, d)


def star(x, y, radius: float, points: int = 5, inner: float = 0.45, soft: float = 0.01):
    """Coverage of a star polygon centred at the origin, one point straight up (+y)."""
    w = np.pi / points
    # Fold every point into the wedge between a tip (angle 0) and the next inner corner (angle w).
    th = np.abs(np.mod(np.arctan2(x, y) + w, 2 * w) - w)
    rad = np.hypot(x, y)
    px, py = rad * np.cos(th), rad * np.sin(th)
    ex, ey = inner * radius * np.cos(w) - radius, inner * radius * np.sin(w)
    d = (ex * py - ey * (px - radius)) / np.hypot(ex, ey)  # signed distance to the edge, > 0 inside
    return smoothstep(-soft, soft, d)


def sample_image(image: np.ndarray, map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
    """Bilinear lookup of a float image at pixel coordinates (centres at integers); 0 outside."""
    return cv2.remap(
        np.ascontiguousarray(image, dtype=np.float32),
        np.ascontiguousarray(map_x, dtype=np.float32),
        np.ascontiguousarray(map_y, dtype=np.float32),
        interpolation=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )


def height_to_normal(height: np.ndarray, texel_w=1.0, texel_h=1.0) -> np.ndarray:
    """Tangent-space normal map (H, W, 3) uint8 from a height field (same length unit as the texel sizes).

    Texel sizes may be arrays broadcastable to (H, W) (a lathe's texels widen with the radius).
    Rows run down the image while the map's +Y runs up, hence the opposite signs of the two slopes.
    """
    h = np.asarray(height, dtype=np.float32)
    dh_dcol = np.gradient(h, axis=1) / np.asarray(texel_w, dtype=np.float32)
    dh_drow = np.gradient(h, axis=0) / np.asarray(texel_h, dtype=np.float32)
    n = np.stack(np.broadcast_arrays(-dh_dcol, dh_drow, np.ones_like(h)), -1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return to_u8(n * 0.5 + 0.5)


def to_u8(x) -> np.ndarray:
    return np.clip(np.rint(np.asarray(x, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def pack_metallic_roughness(roughness: np.ndarray, metallic: np.ndarray) -> np.ndarray:
    """glTF metallicRoughness texture: G = roughness, B = metallic; R = 1 (no occlusion if read as ORM)."""
    r = np.asarray(roughness, dtype=np.float32)
    return to_u8(np.stack([np.ones_like(r), r, np.asarray(metallic, dtype=np.float32) * np.ones_like(r)], -1))


class MaterialCanvas:
    """Base colour (sRGB), roughness, metallic and height, painted together layer by layer."""

    def __init__(self, height: int, width: int, color, roughness: float, metallic: float = 0.0):
        self.shape = (height, width)
        self.albedo = np.empty((height, width, 3), dtype=np.float32)
        self.albedo[:] = srgb(color)
        self.roughness = np.full((height, width), roughness, dtype=np.float32)
        self.metallic = np.full((height, width), metallic, dtype=np.float32)
        self.height = np.zeros((height, width), dtype=np.float32)

    def _mask(self, mask) -> np.ndarray:
        return np.broadcast_to(np.asarray(mask, dtype=np.float32), self.shape)

    def paint(self, mask, color=None, roughness=None, metallic=None, height=None) -> MaterialCanvas:
        """Blend towards the given values where `mask` (broadcastable to (H, W), in [0, 1]) is on.

        `color` is an sRGB triple or an (H, W, 3) array; the others are scalars or (H, W) arrays.
        `height` is added (a relief), not blended.
        """
        m = self._mask(mask)
        # Work on the bounding box of the mask only: most layers cover a band or a patch.
        rows = np.flatnonzero(m.any(axis=1))
        if len(rows) == 0:
            return self
        cols = np.flatnonzero(m.any(axis=0))
        sl = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
        m = m[sl]

        def crop(value, full_shape):
            value = np.asarray(value, dtype=np.float32)
            return np.broadcast_to(value, full_shape)[sl] if value.ndim > 1 else value

        if color is not None:
            a = self.albedo[sl]
            a += (crop(color, self.albedo.shape) - a) * m[..., None]
        for value, target in ((roughness, self.roughness), (metallic, self.metallic)):
            if value is not None:
                tgt = target[sl]
                tgt += (crop(value, self.shape) - tgt) * m
        if height is not None:
            self.height[sl] += crop(height, self.shape) * m
        return self

    def blit(self, other: MaterialCanvas, y0: int, x0: int, height_scale: float = 1.0) -> None:
        """Copy `other` into this canvas with its top-left corner at (y0, x0)."""
        h, w = other.shape
        self.albedo[y0 : y0 + h, x0 : x0 + w] = other.albedo
        self.roughness[y0 : y0 + h, x0 : x0 + w] = other.roughness
        self.metallic[y0 : y0 + h, x0 : x0 + w] = other.metallic
        self.height[y0 : y0 + h, x0 : x0 + w] = other.height * height_scale

    def material(self, name: str, texel_w=1.0, texel_h=1.0, normal_scale: float = 1.0) -> PBRMaterial:
        """The glTF material; a normal map only where some relief was painted."""
        normal = None
        if np.ptp(self.height) > 0:
            normal = height_to_normal(self.height, texel_w, texel_h)
        return PBRMaterial(
            name=name,
            base_color_factor=(1.0, 1.0, 1.0, 1.0),
            metallic_factor=1.0,
            roughness_factor=1.0,
            normal_scale=normal_scale,
            base_color_texture=to_u8(self.albedo),
            metallic_roughness_texture=pack_metallic_roughness(
                np.clip(self.roughness, 0.02, 1.0), np.clip(self.metallic, 0.0, 1.0)
            ),
            normal_texture=normal,
        )
