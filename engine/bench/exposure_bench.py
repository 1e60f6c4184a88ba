"""`lirm bench exposure DEMO_OUT`: how closely a capture reads its photos' exposures and white balances
from their shared backgrounds (capture/exposure_estimate.py), against photos whose truth is known.

The photos of a shoot taken at one exposure and balance (a `lirm demo` output's photos/) are captured
twice, without EXIF: as they are (the control: what the estimate says where nothing moved, and
whether that was left alone), and altered as a phone's automatic exposure and white balance would
(every other photo `apart_stops` darker, each photo's red and blue moved apart by a seeded tint within
`tint_stops`, in linear light through the product's camera curve). The altered capture's estimates
are compared with the alterations (both relative: only differences between photos can be seen).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.exposure_estimate import COLOUR_NOISE_STOPS, ESTIMATE_NOISE_STOPS, colour_spread
from lirm.engine.capture.exposure_match import ESTIMATED_EXPOSURE_KEY, match_exposure
from lirm.engine.errors import LirmUserError
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS as _LUMINANCE


@dataclass(frozen=True)
class ExposureBenchConfig:
    apart_stops: float = 1.0  # every other photo this much darker
    tint_stops: float = 0.15  # each photo's red up and blue down by a tint within +- this (11%)
    seed: int = 0


@dataclass
class EstimateScore:
    spread: float  # the estimated exposures' spread (stops)
    colour_spread: float  # the widest spread of one channel's estimated offset (stops)
    matched: bool
    colour_matched: bool
    lighting_seconds: float  # the lighting stage, which makes the estimate
    exposure_error: float | None = None  # the largest error of a photo's exposure against the truth (stops)
    colour_error: float | None = None  # ... of one channel's offset


@dataclass
class ExposureBenchResult:
    photos: int
    config: ExposureBenchConfig
    control: EstimateScore
    altered: EstimateScore

    def report(self) -> str:
        c, a = self.control, self.altered
        return "\n".join([
            f"exposure and white balance read from the backgrounds of {self.photos} photos "
            f"(matched beyond {ESTIMATE_NOISE_STOPS} EV and {COLOUR_NOISE_STOPS} stops a channel):",
            f"  as taken (one exposure, one balance): spread {c.spread:.2f} EV, {'matched' if c.matched else 'left alone'}; "
            f"balance spread {c.colour_spread:.3f} stops, {'balanced' if c.colour_matched else 'left alone'} "
            f"(lighting stage {c.lighting_seconds:.1f} s)",
            f"  altered (every other photo {self.config.apart_stops:g} EV darker, red and blue apart by up to "
            f"+-{self.config.tint_stops:g} stops, seed {self.config.seed}): exposures within {a.exposure_error:.3f} EV of the "
            f"truth ({'matched' if a.matched else 'NOT matched'}), balances within {a.colour_error:.3f} stops "
            f"({'balanced' if a.colour_matched else 'NOT balanced'}) (lighting stage {a.lighting_seconds:.1f} s)",
        ])


def demo_photos(demo_out: Path) -> list[Path]:
    photos = sorted((Path(demo_out) / "photos").glob("*.jpg"))
    if len(photos) < 2:
        raise LirmUserError(f"{demo_out}: no photos/ of a `lirm demo` output; run `lirm demo -o {demo_out}` first")
    return photos


def alter_photos(photos: list[Path], out: Path, config: ExposureBenchConfig) -> tuple[np.ndarray, np.ndarray]:
    """The photos as automatic exposure and balance would have taken them, as PNG without EXIF in
    `out`; the truth: each photo's exposure (luminance, stops) and red, green, blue offsets (stops)."""
    out.mkdir(parents=True, exist_ok=True)
    tints = np.random.default_rng(config.seed).uniform(-config.tint_stops, config.tint_stops, len(photos))
    exposures, offsets = [], []
    for k, photo in enumerate(photos):
        offset = np.array([tints[k], 0.0, -tints[k]])
        stops = -config.apart_stops if k % 2 else 0.0
        gain = 2.0 ** (offset + stops)
        image = np.asarray(Image.open(photo).convert("RGB"))
        Image.fromarray(match_exposure(image, gain, "aces")).save(out / f"{photo.stem}.png")
        exposures.append(float(np.log2(gain @ _LUMINANCE)))
        offsets.append(offset)
    return np.array(exposures), np.array(offsets)


def run_exposure_bench(demo_out: str | Path, config: ExposureBenchConfig = ExposureBenchConfig(),
                       progress=None) -> ExposureBenchResult:
    from lirm.engine.capture.pipeline import run_capture

    photos = demo_photos(Path(demo_out))
    with tempfile.TemporaryDirectory(prefix="lirm-exposure-bench-") as tmp:
        tmp = Path(tmp)
        as_taken = tmp / "as_taken"
        as_taken.mkdir()
        for photo in photos:  # re-encoded without EXIF, as the altered ones are
            Image.open(photo).convert("RGB").save(as_taken / f"{photo.stem}.png")
        control = _score(run_capture(as_taken, tmp / "control", progress=progress).capture)
        exposures, offsets = alter_photos(photos, tmp / "altered", config)
        capture = run_capture(tmp / "altered", tmp / "capture", progress=progress).capture
        altered = _score(capture, {p.stem: (e, o) for p, e, o in zip(photos, exposures, offsets)})
    return ExposureBenchResult(len(photos), config, control, altered)


def _score(capture: Capture, truth: dict | None = None) -> EstimateScore:
    estimated = capture.settings.get(ESTIMATED_EXPOSURE_KEY)
    if not estimated:
        raise LirmUserError(f"{capture.root}: the capture estimated no exposure (no background shared by the photos?)")
    frames = sorted(estimated["stops"])
    stops = np.array([estimated["stops"][f] for f in frames])
    colour = np.array([estimated["colour_stops"][f] for f in frames])
    score = EstimateScore(float(np.ptp(stops)), colour_spread(estimated["colour_stops"]), bool(estimated["matched"]),
                          bool(estimated["colour_matched"]), float(capture.settings.get("timings", {}).get("lighting", 0.0)))
    if truth is not None:
        names = [capture.frames[f].record.original.stem for f in frames]
        true_stops = np.array([truth[n][0] for n in names])
        true_colour = np.array([truth[n][1] for n in names])
        true_colour = true_colour - true_colour.mean(1, keepdims=True)
        true_colour -= true_colour.mean(0)
        score.exposure_error = float(np.abs((stops - stops.mean()) - (true_stops - true_stops.mean())).max())
        score.colour_error = float(np.abs(colour - true_colour).max())
    return score
