"""Built-in HDR environments drawn procedurally, so nothing has to be downloaded.

Three kinds, each a frozen dataclass config with a named preset in `PROCEDURAL_ENVIRONMENTS`:

- `StudioConfig` ("studio"): dark neutral walls with a gentle vertical gradient, a slightly brighter
  floor, and soft-edged rectangular emitters (key, fill and a rim strip) seen as flat rectangles.
- `SkyConfig` ("sky"): a clear sky, deep blue at the zenith to a bright hazy horizon, a warm sun disc
  (~1.5° angular radius, limb-darkened, anti-aliased edge) with a circumsolar glow, and a ground
  lit by that sky (radiance = ground albedo × irradiance / π).
- `OvercastConfig` ("overcast"): the CIE standard overcast sky L(θ) ∝ (1 + 2 cos θ) / 3 over a grey
  ground lit the same way.

Directions follow `environment.py` (world +Z up, image centre along +X). Azimuths here are
degrees counter-clockwise from +X seen from above (toward +Y), the sense of `rotation_about_z`;
elevations are degrees above the horizon.

Exposure: every environment is scaled so that a white Lambertian surface facing up (+Z) receives
E(+Z)/π = 1.0 in luminance (Rec. 709 weights), E being the cosine-weighted sum of radiance over the
texels with their exact solid angles. The built-ins (and their random variations) therefore all
light an object at the same, well-exposed level, whatever their colours or sun strength; a camera
exposure of 1.0 shows a white diffuse top face at about 1.0.

`config.randomized(rng)` draws a variation from a numpy Generator (deterministic by seed), and
`random_procedural_environment(rng)` picks a kind too: the synthetic-data generator's entry point.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Union

import numpy as np

from .environment import Environment, equirect_uv_to_direction

LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 / sRGB primaries, linear

RGB = tuple[float, float, float]


# ---------------------------------------------------------------------------------------------
# Shared geometry
# ---------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _grid(width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel-centre directions (H, W, 3), per-row solid angle (H,) and per-row top edge theta (H+1,).

    Cached because synthetic data generation asks for the same resolution thousands of times;
    the arrays are made read-only so a caller cannot corrupt the cache.
    """
    h = width // 2
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(u, v)
    dirs = equirect_uv_to_direction(uu, vv)  # (H, W, 3) float64, as Environment.texel_directions
    theta_edges = np.linspace(0.0, np.pi, h + 1)
    row_solid_angle = (np.cos(theta_edges[:-1]) - np.cos(theta_edges[1:])) * (2.0 * np.pi / width)
    for a in (dirs, row_solid_angle, theta_edges):
        a.setflags(write=False)
    return dirs, row_solid_angle, theta_edges


def _sky_coverage(theta_edges: np.ndarray) -> np.ndarray:
    """Fraction (H,) of each row above the horizon: an anti-aliased horizon at any height."""
    top, bottom = theta_edges[:-1], theta_edges[1:]
    return np.clip((np.pi / 2 - top) / (bottom - top), 0.0, 1.0)


def _direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


def _smoothstep(t: np.ndarray) -> np.ndarray:
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMINANCE_WEIGHTS


def _up_irradiance(radiance: np.ndarray, width: int) -> float:
    """Luminance of E(+Z) = sum L(w) max(0, w_z) dOmega over the texels."""
    dirs, row_sa, _ = _grid(width)
    weight = np.maximum(dirs[..., 2], 0.0) * row_sa[:, None]
    return float(_luminance(np.einsum("hwc,hw->c", radiance, weight)))


def _normalized(radiance: np.ndarray, width: int, name: str) -> Environment:
    e = _up_irradiance(radiance, width)
    if not e > 0.0:
        raise ValueError(f"procedural environment {name!r} sends no light onto an up-facing surface")
    return Environment((radiance * (np.pi / e)).astype(np.float32), name=name)


def _check_width(width: int) -> int:
    if int(width) != width or width < 8:
        raise ValueError(f"environment width must be an integer >= 8, got {width!r}")
    return int(width)


def _rgb(value) -> RGB:
    c = tuple(float(x) for x in value)
    if len(c) != 3 or not all(math.isfinite(x) and x >= 0.0 for x in c):
        raise ValueError(f"a colour must be three finite non-negative numbers, got {value!r}")
    return c  # type: ignore[return-value]


def _scaled(c: RGB, k: float) -> RGB:
    return tuple(float(x * k) for x in c)  # type: ignore[return-value]


def _jitter_rgb(rng: np.random.Generator, c: RGB, amount: float) -> RGB:
    """Scale each channel by exp(N(0, amount)): a small tint change that keeps the hue family."""
    return tuple(float(x * math.exp(rng.normal(0.0, amount))) for x in c)  # type: ignore[return-value]


# ---------------------------------------------------------------------------------------------
# Studio
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SoftBox:
    """A flat rectangular emitter facing the origin, centred at (azimuth, elevation).

    width/height are the full angles it subtends through its centre; softness is the width of the
    fall-off band at each edge as a fraction of the half-size (diffusers have soft edges).
    """

    azimuth_deg: float
    elevation_deg: float
    width_deg: float
    height_deg: float
    intensity: float  # radiance at full coverage, relative to the other terms before normalisation
    color: RGB = (1.0, 1.0, 1.0)
    softness: float = 0.25

    def __post_init__(self) -> None:
        object.__setattr__(self, "color", _rgb(self.color))
        if not (0.0 < self.width_deg < 170.0 and 0.0 < self.height_deg < 170.0):
            raise ValueError(f"soft box size must be in (0, 170) degrees, got {self.width_deg}x{self.height_deg}")
        if not (self.intensity >= 0.0 and 0.0 <= self.softness <= 1.0):
            raise ValueError("soft box intensity must be >= 0 and softness in [0, 1]")

    def coverage(self, dirs: np.ndarray, texel_angle: float) -> np.ndarray:
        """(H, W) emitter coverage in [0, 1] by gnomonic projection onto the box's plane."""
        c = _direction(self.azimuth_deg, self.elevation_deg)
        ref = np.array([0.0, 0.0, 1.0]) if abs(c[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
        right = np.cross(ref, c)
        right /= np.linalg.norm(right)
        up = np.cross(c, right)
        halves = [math.tan(math.radians(full) / 2) for full in (self.width_deg, self.height_deg)]
        # Never sharper than ~1.5 texels, so the edge is anti-aliased at any resolution.
        bands = [max(self.softness * half, 1.5 * texel_angle) for half in halves]
        # Only the rows the box can reach are evaluated: most of the panorama is not a box.
        reach = math.atan(math.hypot(*(h + b for h, b in zip(halves, bands)))) + texel_angle
        h = dirs.shape[0]
        theta_c = math.acos(float(np.clip(c[2], -1.0, 1.0)))
        r0 = max(int(math.floor((theta_c - reach) / np.pi * h)) - 1, 0)
        r1 = min(int(math.ceil((theta_c + reach) / np.pi * h)) + 1, h)
        out = np.zeros(dirs.shape[:2])
        d = dirs[r0:r1]
        dc = d @ c
        front = dc > 1e-3
        safe = np.where(front, dc, 1.0)
        cov = front.astype(np.float64)
        for axis, half, band in zip((right, up), halves, bands):
            coord = np.abs(d @ axis) / safe
            cov *= _smoothstep((half - coord) / band + 0.5)
        out[r0:r1] = cov
        return out


@dataclass(frozen=True)
class StudioConfig:
    wall_top: RGB = (0.030, 0.030, 0.031)
    wall_horizon: RGB = (0.055, 0.055, 0.056)
    floor: RGB = (0.085, 0.083, 0.080)
    horizon_softness_deg: float = 6.0  # the floor meets the walls in a soft cove, not a line
    boxes: tuple[SoftBox, ...] = field(
        default_factory=lambda: (
            SoftBox(40.0, 35.0, 48.0, 36.0, intensity=6.0, color=(1.0, 0.97, 0.93)),  # key
            SoftBox(-65.0, 15.0, 40.0, 30.0, intensity=1.8, color=(0.95, 0.97, 1.0)),  # fill
            SoftBox(175.0, 25.0, 10.0, 60.0, intensity=5.0, softness=0.15),  # rim strip
        )
    )
    name: str = "studio"

    def __post_init__(self) -> None:
        for f in ("wall_top", "wall_horizon", "floor"):
            object.__setattr__(self, f, _rgb(getattr(self, f)))
        object.__setattr__(self, "boxes", tuple(self.boxes))
        if not self.horizon_softness_deg >= 0.0:
            raise ValueError("horizon_softness_deg must be >= 0")

    def render(self, width: int = 1024) -> Environment:
        width = _check_width(width)
        dirs, _, _ = _grid(width)
        texel = np.pi / (width // 2)
        z = dirs[:, :1, 2:3]  # walls and floor vary by row only: (H, 1, 1), broadcast later
        top, horizon = np.asarray(self.wall_top), np.asarray(self.wall_horizon)
        wall = horizon + (top - horizon) * np.clip(z, 0.0, 1.0)
        soft = max(math.radians(self.horizon_softness_deg), texel)
        wall_weight = _smoothstep(np.arcsin(np.clip(z, -1.0, 1.0)) / soft + 0.5)
        rows = wall * wall_weight + np.asarray(self.floor) * (1.0 - wall_weight)
        radiance = np.repeat(rows, width, axis=1)
        for box in self.boxes:
            radiance += box.coverage(dirs, texel)[..., None] * (box.intensity * np.asarray(box.color))
        return _normalized(radiance, width, self.name)

    def randomized(self, rng: np.random.Generator) -> "StudioConfig":
        """The same studio re-rigged: rotated, boxes moved, resized, dimmed or brightened, re-tinted."""
        spin = float(rng.uniform(0.0, 360.0))
        boxes = tuple(
            dataclasses.replace(
                b,
                azimuth_deg=float((b.azimuth_deg + spin + rng.normal(0.0, 12.0)) % 360.0),
                elevation_deg=float(np.clip(b.elevation_deg + rng.normal(0.0, 8.0), -5.0, 80.0)),
                width_deg=float(np.clip(b.width_deg * rng.uniform(0.7, 1.4), 3.0, 120.0)),
                height_deg=float(np.clip(b.height_deg * rng.uniform(0.7, 1.4), 3.0, 120.0)),
                intensity=float(b.intensity * rng.uniform(0.5, 1.6)),
                color=_jitter_rgb(rng, b.color, 0.05),
                softness=float(np.clip(b.softness * rng.uniform(0.5, 1.8), 0.02, 1.0)),
            )
            for b in self.boxes
        )
        level = float(rng.uniform(0.6, 1.6))
        return dataclasses.replace(
            self,
            wall_top=_scaled(_jitter_rgb(rng, self.wall_top, 0.04), level),
            wall_horizon=_scaled(_jitter_rgb(rng, self.wall_horizon, 0.04), level),
            floor=_scaled(_jitter_rgb(rng, self.floor, 0.06), level),
            boxes=boxes,
        )


# ---------------------------------------------------------------------------------------------
# Clear sky with a sun
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SkyConfig:
    sun_elevation_deg: float = 35.0
    sun_azimuth_deg: float = 120.0
    sun_radius_deg: float = 1.5  # ~6x the real sun: resolvable at 1k and gives soft-ish shadows
    sun_color: RGB = (1.0, 0.88, 0.72)
    # Sun irradiance on a surface facing it, over sky-only irradiance on an up-facing surface.
    # A clear day is about 3-8; it sets how hard the shadows are, not how bright the scene is.
    sun_to_sky_ratio: float = 5.0
    limb_darkening: float = 0.6  # the disc is brighter at its centre, as the real sun is
    zenith_color: RGB = (0.10, 0.25, 0.80)
    horizon_color: RGB = (0.75, 0.84, 1.0)
    horizon_haze: float = 0.18  # how far (in cos θ) the bright horizon band reaches up
    glow_strength: float = 1.2  # circumsolar glow at the sun, relative to the horizon colour
    glow_width_deg: float = 12.0
    ground_albedo: RGB = (0.18, 0.16, 0.13)
    name: str = "sky"

    def __post_init__(self) -> None:
        for f in ("sun_color", "zenith_color", "horizon_color", "ground_albedo"):
            object.__setattr__(self, f, _rgb(getattr(self, f)))
        if not -90.0 <= self.sun_elevation_deg <= 90.0:
            raise ValueError(f"sun_elevation_deg must be in [-90, 90], got {self.sun_elevation_deg}")
        if not 0.0 < self.sun_radius_deg <= 20.0:
            raise ValueError(f"sun_radius_deg must be in (0, 20], got {self.sun_radius_deg}")
        if not (self.sun_to_sky_ratio >= 0 and self.glow_strength >= 0 and self.horizon_haze > 0):
            raise ValueError("sun_to_sky_ratio and glow_strength must be >= 0, horizon_haze > 0")
        if not (0.0 <= self.limb_darkening <= 1.0 and self.glow_width_deg > 0):
            raise ValueError("limb_darkening must be in [0, 1] and glow_width_deg > 0")

    @property
    def sun_direction(self) -> np.ndarray:
        return _direction(self.sun_azimuth_deg, self.sun_elevation_deg)

    def render(self, width: int = 1024) -> Environment:
        width = _check_width(width)
        dirs, row_sa, theta_edges = _grid(width)
        texel = np.pi / (width // 2)
        z = np.clip(dirs[..., 2], 0.0, 1.0)
        above = _sky_coverage(theta_edges)[:, None]
        sun = self.sun_direction
        gamma = np.arccos(np.clip(dirs @ sun, -1.0, 1.0))  # angle to the sun

        zenith, horizon = np.asarray(self.zenith_color), np.asarray(self.horizon_color)
        t = np.exp(-z / self.horizon_haze)[..., None]
        sky = zenith + (horizon - zenith) * t
        glow = np.exp(-gamma / math.radians(self.glow_width_deg))[..., None]
        sky = sky + self.glow_strength * glow * _luminance(horizon) * np.asarray(self.sun_color)
        sky = sky * above[..., None]
        e_sky = _up_irradiance(sky, width)

        # Limb-darkened disc with a smooth edge at least ~2 texels wide (no aliasing at any width).
        r = math.radians(self.sun_radius_deg)
        edge = max(math.radians(0.25), 2.0 * texel)
        inside = _smoothstep((r - gamma) / edge + 0.5)
        mu = np.sqrt(np.clip(1.0 - (gamma / r) ** 2, 0.0, 1.0))
        profile = inside * (1.0 - self.limb_darkening * (1.0 - mu)) * above
        disc_sa = float(np.sum(profile * row_sa[:, None]))
        radiance = sky
        e_total = e_sky
        if disc_sa > 0.0 and self.sun_to_sky_ratio > 0.0:
            sun_rgb = np.asarray(self.sun_color) / _luminance(np.asarray(self.sun_color))
            scale = self.sun_to_sky_ratio * e_sky / disc_sa
            radiance = radiance + profile[..., None] * (scale * sun_rgb)
            e_total = _up_irradiance(radiance, width)

        ground = np.asarray(self.ground_albedo) * (e_total / np.pi)
        radiance = radiance + (1.0 - above)[..., None] * ground
        return _normalized(radiance, width, self.name)

    def randomized(self, rng: np.random.Generator) -> "SkyConfig":
        """Another clear day: sun anywhere above 3°, warmer when low, varying haze and ground."""
        elevation = float(rng.uniform(3.0, 75.0))
        low = 1.0 - min(elevation, 40.0) / 40.0  # 1 near the horizon, 0 from 40° up
        sun_color = (1.0, 0.92 - 0.25 * low, 0.82 - 0.45 * low)
        haze = float(rng.uniform(0.0, 1.0))  # 0: deep clear blue, 1: milky
        zenith = tuple(z + (h - z) * 0.45 * haze for z, h in zip(self.zenith_color, self.horizon_color))
        return dataclasses.replace(
            self,
            sun_elevation_deg=elevation,
            sun_azimuth_deg=float(rng.uniform(0.0, 360.0)),
            sun_color=_jitter_rgb(rng, sun_color, 0.03),
            sun_to_sky_ratio=float(rng.uniform(2.0, 9.0) * (1.0 - 0.5 * haze)),
            zenith_color=_jitter_rgb(rng, zenith, 0.08),
            horizon_color=_jitter_rgb(rng, self.horizon_color, 0.04),
            horizon_haze=float(rng.uniform(0.1, 0.35)),
            glow_strength=float(rng.uniform(0.5, 2.5)),
            glow_width_deg=float(rng.uniform(6.0, 20.0)),
            ground_albedo=_jitter_rgb(rng, _scaled(self.ground_albedo, rng.uniform(0.5, 1.8)), 0.1),
        )


# ---------------------------------------------------------------------------------------------
# Overcast sky
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OvercastConfig:
    sky_color: RGB = (0.96, 0.98, 1.0)
    ground_albedo: RGB = (0.2, 0.2, 0.2)
    name: str = "overcast"

    def __post_init__(self) -> None:
        for f in ("sky_color", "ground_albedo"):
            object.__setattr__(self, f, _rgb(getattr(self, f)))

    def render(self, width: int = 1024) -> Environment:
        width = _check_width(width)
        dirs, _, theta_edges = _grid(width)
        above = _sky_coverage(theta_edges)[:, None]
        cie = (1.0 + 2.0 * np.clip(dirs[..., 2], 0.0, 1.0)) / 3.0  # CIE standard overcast sky
        sky = (cie * above)[..., None] * np.asarray(self.sky_color)
        ground = np.asarray(self.ground_albedo) * (_up_irradiance(sky, width) / np.pi)
        return _normalized(sky + (1.0 - above)[..., None] * ground, width, self.name)

    def randomized(self, rng: np.random.Generator) -> "OvercastConfig":
        return dataclasses.replace(
            self,
            sky_color=_jitter_rgb(rng, self.sky_color, 0.04),
            ground_albedo=_jitter_rgb(rng, _scaled(self.ground_albedo, rng.uniform(0.5, 1.6)), 0.05),
        )


ProceduralConfig = Union[StudioConfig, SkyConfig, OvercastConfig]

PROCEDURAL_ENVIRONMENTS: dict[str, ProceduralConfig] = {
    "studio": StudioConfig(),
    "sky": SkyConfig(),
    "overcast": OvercastConfig(),
}


def make_procedural_environment(name: str | ProceduralConfig, width: int = 1024) -> Environment:
    """A built-in environment by preset name (or from a config), width x width // 2, normalised."""
    if isinstance(name, (StudioConfig, SkyConfig, OvercastConfig)):
        return name.render(width)
    try:
        config = PROCEDURAL_ENVIRONMENTS[name]
    except (KeyError, TypeError):
        valid = ", ".join(PROCEDURAL_ENVIRONMENTS)
        raise ValueError(f"unknown procedural environment {name!r}; valid names: {valid}") from None
    return config.render(width)


def random_procedural_environment(
    rng: np.random.Generator, width: int = 1024, names: tuple[str, ...] | None = None
) -> Environment:
    """A random variation of a randomly chosen preset (for synthetic data), deterministic by rng."""
    names = tuple(names) if names is not None else tuple(PROCEDURAL_ENVIRONMENTS)
    for n in names:
        if n not in PROCEDURAL_ENVIRONMENTS:
            raise ValueError(f"unknown procedural environment {n!r}; valid names: {', '.join(PROCEDURAL_ENVIRONMENTS)}")
    name = names[int(rng.integers(len(names)))]
    return PROCEDURAL_ENVIRONMENTS[name].randomized(rng).render(width)
