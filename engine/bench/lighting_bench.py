"""`lirm bench lighting DEMO_OUT`: the capture lighting estimated from the demo shoot's photos against
the environment the demo rendered them under (issue 19's figures), after aligning the capture's
world frame to the shoot's by the camera centres."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lirm.engine.assets.environment_files import resolve_environment
from lirm.engine.cameras import Camera
from lirm.engine.capture.alignment import similarity_align
from lirm.engine.capture.capture_folder import Capture
from lirm.engine.evaluation.lighting_accuracy import LightingAccuracy, compare_lighting


@dataclass
class LightingBenchResult:
    accuracy: LightingAccuracy
    environment: str
    seen_fraction: float | None

    def report(self) -> str:
        a = self.accuracy
        lines = [f"capture lighting against the shoot's true environment ({self.environment}):",
                 f"  brightest 1%: {a.brightest_angle_deg:.1f} degrees from the truth (goal: within 20)",
                 f"  irradiance on an upward-facing plane: {a.up_irradiance_ratio:.2f} x the truth (goal: 0.75-1.25)"]
        if self.seen_fraction is not None:
            lines.append(f"  directions the photos saw: {100 * self.seen_fraction:.0f}% (the rest is filled, not measured)")
        return "\n".join(lines)


def run_lighting_bench(demo_out: str | Path, environment: str | None = None) -> LightingBenchResult:
    demo_out = Path(demo_out)
    capture = Capture.open(demo_out / "capture")
    truth_file = json.loads((demo_out / "truth" / "transforms.json").read_text())
    environment = environment or truth_file.get("environment", "sky")
    truth_cameras = {Path(f["file_path"]).stem: Camera.from_dict(f) for f in truth_file["frames"]}
    pairs = [(capture.cameras[fid].center, truth_cameras[state.record.original.stem].center)
             for fid, state in capture.frames.items()
             if fid in capture.cameras and state.record.original.stem in truth_cameras]
    _, rotation, _ = similarity_align(np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))
    estimate = resolve_environment(demo_out / "capture")
    truth = resolve_environment(environment, width=int(truth_file.get("environment_width", 1024)))
    info_file = demo_out / "capture" / "lighting" / "lighting.json"
    seen = json.loads(info_file.read_text()).get("seen_fraction") if info_file.is_file() else None
    return LightingBenchResult(compare_lighting(estimate, truth, rotation), environment, seen)
