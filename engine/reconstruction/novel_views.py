"""Cameras for looking at a reconstruction: an orbit around the normalised object at the capture's
typical distance, elevation and field of view. Azimuth 0 is the side the first photo saw
(normalisation turns the first camera to look along +Y, like the orbit's azimuth 0)."""

from __future__ import annotations

import numpy as np

from lirm.engine.cameras import Camera, orbit_cameras


def novel_view_cameras(input_cameras: list[Camera], count: int, size: int, start_azimuth_deg: float = 45.0) -> list[Camera]:
    centres = np.array([c.center for c in input_cameras])
    distances = np.linalg.norm(centres, axis=1)
    distance = float(np.median(distances))
    elevation = float(np.degrees(np.median(np.arcsin(np.clip(centres[:, 2] / np.maximum(distances, 1e-9), -1, 1)))))
    fov = float(np.median([min(c.fov_x_deg, c.fov_y_deg) for c in input_cameras]))
    # Wide enough to see the whole bounding sphere of radius 1 from that distance.
    fov = max(fov, float(np.degrees(2.0 * np.arcsin(min(1.0 / max(distance, 1.0 + 1e-6), 1.0)))) + 2.0)
    return orbit_cameras(count, elevation, distance, size, size, fov, start_azimuth_deg=start_azimuth_deg)
