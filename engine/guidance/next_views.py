"""Candidate viewpoints on the view sphere, and the greedy choice of the next k to shoot.

Candidates: elevations -10..80 degrees, every `azimuth_step` degrees, at the capture's typical
distance and field of view (what a photographer walking round the object can reach). Each candidate
is worth how much it would raise the viewing quality of the (weighted) surface: newly covered
points first, then points seen only obliquely so far; the best is taken, and the next is chosen
the same way on what it leaves. Weights default to 1 (pure coverage); the model's
uncertainty can raise them where the reconstruction is unsure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.cameras import Camera, orbit_camera

from .coverage import SurfaceCoverage


@dataclass(frozen=True)
class CandidateConfig:
    elevations_deg: tuple[float, ...] = (-10.0, 0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0)
    azimuth_step_deg: float = 15.0
    size: int = 256


@dataclass
class Suggestion:
    azimuth_deg: float
    elevation_deg: float
    distance: float
    look_at: tuple[float, float, float]
    gain: float  # the rise in (weighted) viewing quality this view brings, as a share of the surface (choose_greedily)
    new_coverage: float  # share of the surface it newly covers (seen within 60°), after the suggestions before it
    sentence: str
    camera: Camera


def camera_angles(camera: Camera, target: np.ndarray = np.zeros(3)) -> tuple[float, float, float]:
    """(azimuth, elevation, distance) of a camera around `target`, in orbit_camera's convention."""
    d = camera.center - target
    distance = float(np.linalg.norm(d))
    elevation = float(np.degrees(np.arcsin(np.clip(d[2] / max(distance, 1e-12), -1, 1))))
    azimuth = float(np.degrees(np.arctan2(d[0], -d[1])) % 360.0)
    return azimuth, elevation, distance


def candidate_cameras(existing: list[Camera], config: CandidateConfig = CandidateConfig()) -> list[tuple[float, float, Camera]]:
    distance = float(np.median([camera_angles(c)[2] for c in existing])) if existing else 2.5
    fov = float(np.median([c.fov_x_deg for c in existing])) if existing else 50.0
    out = []
    for elevation in config.elevations_deg:
        for azimuth in np.arange(0.0, 360.0, config.azimuth_step_deg):
            out.append((float(azimuth), elevation, orbit_camera(float(azimuth), elevation, distance, config.size, config.size, fov)))
    return out


def describe_move(from_azimuth: float, from_elevation: float, to_azimuth: float, to_elevation: float) -> str:
    """A photographer's sentence: azimuth grows counter-clockwise seen from above, which is walking to
    one's right while facing the object."""
    turn = (to_azimuth - from_azimuth + 180.0) % 360.0 - 180.0
    parts = []
    if abs(turn) >= 10.0:
        side = "right" if turn > 0 else "left"
        parts.append("go round to the other side" if abs(turn) > 150 else f"move {abs(turn):.0f}° to your {side}")
    rise = to_elevation - from_elevation
    if abs(rise) >= 10.0:
        parts.append(f"{'raise' if rise > 0 else 'lower'} the camera by {abs(rise):.0f}°"
                     + (" (look down on it)" if to_elevation >= 50 else " (from below)" if to_elevation < 0 else ""))
    return (" and ".join(parts) or "shoot again from about here").capitalize()


def greedy_views(coverage: SurfaceCoverage, existing: list[Camera], candidates: list[Camera], k: int,
                 weights: np.ndarray | None = None, graded: bool = True) -> tuple[list[int], list[float], np.ndarray]:
    """Indices of the k candidates that add the most, chosen one after the other, their gains, and
    every candidate's gain before any choice (see choose_greedily)."""
    now = coverage.view_cosines(existing).max(axis=0, initial=0.0)
    return choose_greedily(now, coverage.view_cosines(candidates), k, weights, graded)


def choose_greedily(quality_now: np.ndarray, looks: np.ndarray, k: int, weights: np.ndarray | None = None,
                    graded: bool = True) -> tuple[list[int], list[float], np.ndarray]:
    """The greedy choice on viewing cosines: `quality_now` (N,) per surface point, `looks` (C, N) per
    candidate (SurfaceCoverage.view_cosines: 0 unseen, 0.5-1 seen within 60°).

    A point's quality is how squarely the best camera so far sees it. A candidate is worth the
    weighted rise in quality it brings, as a share of the weighted surface: a newly covered point adds
    its cosine (0.5-1), a point seen only obliquely so far adds the difference. So new coverage comes
    first, and once the surface is covered the next views still go where it is seen worst.
    `graded=False`: binary coverage (a point seen within 60° counts as done; the gain is the share of
    the surface newly covered)."""
    now = np.asarray(quality_now, np.float64)
    looks = np.asarray(looks, np.float64).reshape(-1, len(now))
    weights = np.ones(len(now)) if weights is None else np.asarray(weights, np.float64)
    total = float(weights.sum()) or 1.0
    if not graded:
        now, looks = (now > 0).astype(np.float64), (looks > 0).astype(np.float64)

    def gains_now() -> np.ndarray:
        return np.maximum(looks - now[None], 0.0) @ weights / total

    first = gains_now()
    chosen, gains = [], []
    for _ in range(min(k, len(looks))):
        gain = gains_now()
        gain[chosen] = -1.0
        best = int(np.argmax(gain))
        if gain[best] <= 1e-9:
            break
        chosen.append(best)
        gains.append(float(gain[best]))
        now = np.maximum(now, looks[best])
    return chosen, gains, first


def farthest_views(existing: list[Camera], candidates: list[Camera], k: int, exclude: tuple[int, ...] = ()) -> list[int]:
    """Indices of k candidates chosen one after the other as the one whose viewing direction is the
    farthest (largest smallest angle) from every view so far: where to shoot when no view adds
    coverage any more, so that the photos keep spreading round the object instead of bunching."""
    def direction(camera: Camera) -> np.ndarray:
        return camera.center / max(float(np.linalg.norm(camera.center)), 1e-12)

    taken = [direction(c) for c in existing] + [direction(candidates[i]) for i in exclude]
    options = [i for i in range(len(candidates)) if i not in set(exclude)]
    chosen = []
    for _ in range(min(k, len(options))):
        def nearest(i: int) -> float:
            d = direction(candidates[i])
            return max((float(d @ t) for t in taken), default=-1.0)  # the cosine to the closest view so far (the largest)
        best = min(options, key=nearest)
        chosen.append(best)
        options.remove(best)
        taken.append(direction(candidates[best]))
    return chosen


def suggest_next_views(coverage: SurfaceCoverage, existing: list[Camera], k: int = 4,
                       weights: np.ndarray | None = None, config: CandidateConfig = CandidateConfig(),
                       quality_now: np.ndarray | None = None) -> tuple[list[Suggestion], np.ndarray]:
    """The next k views (greedy) and every candidate's initial gain as a (elevations, azimuths) heat map."""
    candidates = candidate_cameras(existing, config)
    now = coverage.view_cosines(existing).max(axis=0, initial=0.0) if quality_now is None else np.asarray(quality_now)
    looks = coverage.view_cosines([camera for _, _, camera in candidates])
    chosen, gains, first = choose_greedily(now, looks, k, weights)
    covered = now > 0
    azimuths = np.arange(0.0, 360.0, config.azimuth_step_deg)
    heat_map = first.reshape(len(config.elevations_deg), len(azimuths))
    last = camera_angles(existing[-1]) if existing else (0.0, 20.0, 2.5)
    suggestions = []
    for best, gain in zip(chosen, gains):
        azimuth, elevation, camera = candidates[best]
        new = float((~covered & (looks[best] > 0)).mean())  # what the photographer is told: surface newly covered
        covered |= looks[best] > 0
        suggestions.append(Suggestion(azimuth, elevation, camera_angles(camera)[2], (0.0, 0.0, 0.0), gain, new,
                                      describe_move(last[0], last[1], azimuth, elevation), camera))
        last = (azimuth, elevation)
    return suggestions, heat_map
