"""How close an estimated environment is to the true one: where its brightest light is, and how
much light it sends onto an upward-facing plane (issue 19's two figures); and, to say why they are
off, where that plane's light comes from by elevation (a sun's band, a sky's) and its colour."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.renderer.environment import Environment

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
# Elevation bands (degrees) the up-plane irradiance is split over: the horizon's, the low sky's, a
# mid-height sun's and the zenith's.
ELEVATION_BANDS = ((0.0, 10.0), (10.0, 30.0), (30.0, 60.0), (60.0, 90.0))


def _texel_directions(environment: Environment, to_frame: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(texels, 3) unit directions, rotated by `to_frame` (3x3) when given, and (texels,) solid angles."""
    dirs, solid_angle = environment.texel_directions()
    dirs = dirs.reshape(-1, 3)
    if to_frame is not None:
        dirs = dirs @ np.asarray(to_frame).T
    return dirs, solid_angle.ravel()


def brightest_direction(environment: Environment, fraction: float = 0.01, to_frame: np.ndarray | None = None) -> np.ndarray:
    """Unit mean direction of the brightest `fraction` of the sphere (by solid angle), weighted by
    luminance x solid angle. `to_frame` (3x3) rotates the environment's directions first."""
    dirs, solid_angle = _texel_directions(environment, to_frame)
    luminance = environment.radiance.reshape(-1, 3) @ LUMINANCE
    order = np.argsort(-luminance)
    cumulative = np.cumsum(solid_angle[order])
    top = order[: int(np.searchsorted(cumulative, fraction * 4.0 * np.pi)) + 1]
    mean = (dirs[top] * (luminance[top] * solid_angle[top])[:, None]).sum(0)
    return mean / max(np.linalg.norm(mean), 1e-12)


def up_irradiance(environment: Environment, to_frame: np.ndarray | None = None, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """RGB irradiance on a plane facing `up`: the integral of L cos(theta) over its hemisphere."""
    dirs, solid_angle = _texel_directions(environment, to_frame)
    cosine = np.clip(dirs @ np.asarray(up, dtype=np.float64), 0.0, None)
    return (environment.radiance.reshape(-1, 3) * (cosine * solid_angle)[:, None]).sum(0)


def up_irradiance_by_elevation(environment: Environment, to_frame: np.ndarray | None = None,
                               bands=ELEVATION_BANDS) -> np.ndarray:
    """(len(bands),) luminance irradiance on an upward-facing plane from the directions of each band
    of elevation (degrees, lower bound included); over bands covering 0-90 they sum to up_irradiance's."""
    dirs, solid_angle = _texel_directions(environment, to_frame)
    elevation = np.degrees(np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0)))
    contribution = (environment.radiance.reshape(-1, 3) @ LUMINANCE) * np.clip(dirs[:, 2], 0.0, None) * solid_angle
    return np.array([contribution[(elevation >= lo) & ((elevation < hi) | (hi >= 90.0))].sum() for lo, hi in bands])


def chromaticity(rgb: np.ndarray) -> np.ndarray:
    """r, g, b shares of an RGB quantity (summing to 1): its colour without its brightness."""
    rgb = np.asarray(rgb, dtype=np.float64)
    return rgb / max(float(rgb.sum()), 1e-12)


@dataclass
class LightingAccuracy:
    brightest_angle_deg: float  # between the brightest 1%'s mean directions
    up_irradiance_ratio: float  # estimated / true, luminance
    estimated_up_irradiance: np.ndarray
    true_up_irradiance: np.ndarray
    estimated_by_elevation: np.ndarray  # luminance up-plane irradiance per ELEVATION_BANDS band
    true_by_elevation: np.ndarray

    def meets_goal(self, angle_deg: float = 20.0, irradiance_tolerance: float = 0.25) -> bool:
        return self.brightest_angle_deg <= angle_deg and abs(self.up_irradiance_ratio - 1.0) <= irradiance_tolerance


def compare_lighting(estimate: Environment, truth: Environment, estimate_to_truth: np.ndarray) -> LightingAccuracy:
    """`estimate_to_truth` (3x3) rotates the estimate's world frame into the truth's."""
    a = brightest_direction(estimate, to_frame=estimate_to_truth)
    b = brightest_direction(truth)
    angle = float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))
    e_est = up_irradiance(estimate, to_frame=estimate_to_truth)
    e_true = up_irradiance(truth)
    return LightingAccuracy(angle, float((e_est @ LUMINANCE) / max(e_true @ LUMINANCE, 1e-12)), e_est, e_true,
                            up_irradiance_by_elevation(estimate, to_frame=estimate_to_truth), up_irradiance_by_elevation(truth))
