"""The supplementary's test protocol as a fixed, seeded camera set.

Per object: 48 cameras at elevations {0, 20, 40} degrees x 16 azimuths, FoV 50 degrees, at the
smallest distance where the bounding sphere fits. The inputs are sampled from the 20 and 40 degree
rings in sets of 4 (one set per update); 12 output views are sampled from the cameras no input set
uses. Seeded, so every evaluation sees the same views.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.cameras import Camera

from .object_views import protocol_cameras

ELEVATIONS_DEG = (0.0, 20.0, 40.0)
AZIMUTHS = 16


@dataclass(frozen=True)
class ProtocolConfig:
    size: int = 256
    fov_deg: float = 50.0
    radius: float = 1.0  # the bounding sphere the cameras must cover
    input_sets: int = 4  # updates' worth of inputs
    views_per_set: int = 4
    output_views: int = 12
    seed: int = 0


@dataclass
class ProtocolViews:
    cameras: list[Camera]  # all 48: index = ring * 16 + azimuth step
    elevations_deg: list[float]
    azimuths_deg: list[float]
    input_sets: list[list[int]]  # indices into cameras, one list per update
    outputs: list[int]  # indices into cameras, never an input


def protocol_views(config: ProtocolConfig = ProtocolConfig(), object_index: int = 0) -> ProtocolViews:
    """The protocol's cameras and the seeded choice of inputs and outputs for one object."""
    needed = config.input_sets * config.views_per_set
    if needed > 2 * AZIMUTHS:
        raise ValueError(f"{config.input_sets} sets of {config.views_per_set} inputs need {needed} views; "
                         f"the 20 and 40 degree rings have {2 * AZIMUTHS}")
    elevations = [e for e in ELEVATIONS_DEG for _ in range(AZIMUTHS)]
    azimuths = [360.0 * step / AZIMUTHS for _ in ELEVATIONS_DEG for step in range(AZIMUTHS)]
    cameras = protocol_cameras(azimuths, elevations, config.size, config.fov_deg, config.radius)
    rng = np.random.default_rng([config.seed, object_index])
    candidates = [i for i, e in enumerate(elevations) if e in (20.0, 40.0)]
    chosen = [int(i) for i in rng.choice(candidates, size=needed, replace=False)]
    sets = [chosen[k * config.views_per_set:(k + 1) * config.views_per_set] for k in range(config.input_sets)]
    rest = [i for i in range(len(cameras)) if i not in set(chosen)]
    outputs = sorted(int(i) for i in rng.choice(rest, size=min(config.output_views, len(rest)), replace=False))
    return ProtocolViews(cameras, elevations, azimuths, sets, outputs)
