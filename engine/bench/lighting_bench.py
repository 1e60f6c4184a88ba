"""`lirm bench lighting DEMO_OUT`: the capture lighting estimated from the demo shoot's photos against
the environment the demo rendered them under (issue 19's figures), after aligning the capture's
world frame to the shoot's by the camera centres."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path


from lirm.engine.assets.environment_files import resolve_environment
from lirm.engine.capture.capture_folder import Capture
from lirm.engine.errors import LirmUserError
from lirm.engine.evaluation.lighting_accuracy import ELEVATION_BANDS, LightingAccuracy, chromaticity, compare_lighting

from .shoot_frame import shoot_similarity


@dataclass
class LightingBenchResult:
    accuracy: LightingAccuracy
    environment: str
    seen_fraction: float | None
    source: str = "the backgrounds' estimate (as photographed)"

    def report(self) -> str:
        a = self.accuracy
        lines = [f"capture lighting ({self.source}) against the shoot's true environment ({self.environment}):",
                 f"  brightest 1%: {a.brightest_angle_deg:.1f} degrees from the truth (goal: within 20)",
                 f"  irradiance on an upward-facing plane: {a.up_irradiance_ratio:.2f} x the truth (goal: 0.75-1.25)"]
        bands = ", ".join(f"{lo:g}-{hi:g} deg {e:.2f} / {t:.2f}" for (lo, hi), e, t
                          in zip(ELEVATION_BANDS, a.estimated_by_elevation, a.true_by_elevation))
        lines.append(f"    from each band of elevation (this / truth, luminance): {bands}")
        shares = lambda rgb: " / ".join(f"{c:.2f}" for c in chromaticity(rgb))  # noqa: E731
        lines.append(f"    its colour (r / g / b shares): {shares(a.estimated_up_irradiance)}, truth {shares(a.true_up_irradiance)}")
        if self.seen_fraction is not None:
            lines.append(f"  directions the photos saw: {100 * self.seen_fraction:.0f}% (the rest is filled, not measured)")
        return "\n".join(lines)


def refined_lighting_file(capture: Capture) -> Path | None:
    """The lighting.hdr the capture's latest refinement with materials fitted, if any."""
    for entry in reversed(capture.updates):
        if entry.get("kind") == "refine" and entry.get("state"):
            candidate = capture.root / Path(entry["state"]).parent / "lighting.hdr"
            if candidate.is_file():
                return candidate
    return None


def run_lighting_bench(demo_out: str | Path, environment: str | None = None, refined: bool = False) -> LightingBenchResult:
    """`refined`: the lighting the latest refinement fitted with the materials (the inverse rendering,
    starting from the backgrounds' estimate) instead of the estimate itself."""
    demo_out = Path(demo_out)
    capture = Capture.open(demo_out / "capture")
    truth_file = json.loads((demo_out / "truth" / "transforms.json").read_text())
    environment_override = environment
    environment = environment or truth_file.get("environment", "sky")
    _, rotation, _ = shoot_similarity(capture, truth_file)
    source = "the backgrounds' estimate (as photographed)"
    if refined:
        fitted = refined_lighting_file(capture)
        if fitted is None:
            raise LirmUserError(f"{demo_out / 'capture'}: no refinement with materials there (no lighting.hdr beside a "
                                "refined state); run `lirm refine CAPTURE --materials` or `lirm demo` first")
        estimate, source = resolve_environment(fitted), f"fitted with the materials, {fitted.relative_to(demo_out)}"
    else:
        estimate = resolve_environment(demo_out / "capture")
    if environment_override is None and truth_file.get("lighting_file"):
        # The object's own lighting: the environment with the set's lit ground below (the demo writes it).
        truth = resolve_environment(demo_out / "truth" / truth_file["lighting_file"])
        environment = f"{environment} over the ground, truth/{truth_file['lighting_file']}"
    else:
        truth = resolve_environment(environment, width=int(truth_file.get("environment_width", 1024)))
    info_file = demo_out / "capture" / "lighting" / "lighting.json"
    seen = json.loads(info_file.read_text()).get("seen_fraction") if info_file.is_file() else None
    return LightingBenchResult(compare_lighting(estimate, truth, rotation), environment, seen, source)
