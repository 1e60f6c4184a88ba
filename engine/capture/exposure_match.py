"""Photos exposed apart, brought to one exposure before anything compares them.

A phone exposes every shot on its own: walking round an object with a window on one side moves the
exposure by a stop or more between shots, and everything after ingest (the lighting from the
backgrounds, LIRM's inputs, the refinement's photometric terms, the export's texture fit, the held-out
views) compares a pixel of one photo with a pixel of another as the same radiance. The EXIF says how
each was exposed (exif_exposure.py: stops = log2(time x ISO / 100 / f-number^2)), so each photo's
linear radiance can be scaled to a common exposure: through the capture's camera curve to linear
light, times 2^(reference - stops), and back. Where a photo's EXIF does not say, the lighting stage
reads every photo's exposure from the backgrounds they share instead (exposure_estimate.py), and
those are matched the same way when the estimate is clear enough.

The reference is the most exposed photo, so every other photo is brightened, never darkened: a
pixel the camera clipped stays clipped (the lighting estimate and the texture fit read a clipped value
as "at least this bright"); darkening would turn it into a plain value and lose that. (A white
balance, matched the same way, may darken a channel by a few percent; the pixels clipped in it are
held at their value.) What it cannot undo: highlights a darker shot held and the brightening clips, a phone's local tone mapping that
differs between shots, and photos of several cameras (their sensitivities differ for the same ISO).

Only the working copies made for the reconstruction change (the crops, the images the lighting is
estimated from); the photos and the capture's working images stay as they were taken.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from lirm.engine.lighting.camera_response import RESPONSES, display_to_radiance, radiance_to_display
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS as _LUMINANCE

from .exposure_estimate import COLOUR_NOISE_STOPS, ESTIMATE_NOISE_STOPS, MAX_RESIDUAL_STOPS, colour_spread

# Exposures this close are the same: EXIF rounds a shutter time (1/60 written for 1/64 is 0.09 EV).
SAME_EXPOSURE_STOPS = 0.1
CLIPPED_DISPLAY = 250.0 / 255.0  # a display value this high was clipped (CaptureLightingConfig.clip_level)


def exposure_gains(stops: Mapping[str, float | None], same_within: float = SAME_EXPOSURE_STOPS) -> dict[str, float] | None:
    """Per frame, the factor on its linear radiance that makes it as exposed as the most exposed
    frame: 2^(max - stops), 1 for that frame. None when the photos need no matching (all within
    `same_within` stops) or cannot be matched (a frame without EXIF exposure: its place is unknown)."""
    if len(stops) < 2 or any(s is None for s in stops.values()):
        return None
    most = max(stops.values())
    if most - min(stops.values()) <= same_within:
        return None
    return {frame: float(2.0 ** (most - s)) for frame, s in stops.items()}


def match_exposure(image: np.ndarray, gain, response: str) -> np.ndarray:
    """`image` (H, W, 3 or 4; uint8, or float display values in [0, 1]) with its linear radiance
    multiplied by `gain` (a number, or one per red, green, blue) through the camera curve `response`
    (camera_response.RESPONSES); the same dtype, an alpha channel untouched. A gain of 1 returns the
    image itself."""
    gain = np.asarray(gain, np.float64)
    if np.all(gain == 1.0):
        return image
    if gain.shape not in ((), (3,)) or not np.all(gain > 0) or not np.all(np.isfinite(gain)):
        raise ValueError(f"an exposure gain must be a positive number (or three), got {gain}")
    if response not in RESPONSES:
        raise ValueError(f"unknown camera response {response!r}; choose one of {', '.join(RESPONSES)}")
    integer = image.dtype == np.uint8
    colour = image[..., :3].astype(np.float64) / 255.0 if integer else np.asarray(image[..., :3], np.float64)
    matched = radiance_to_display(display_to_radiance(colour, response) * gain, response)
    # A channel the camera clipped says "at least this bright": a gain below 1 (a white balance's) must
    # not turn it into a plain value.
    held = (colour >= CLIPPED_DISPLAY) & (matched < colour)
    matched[held] = colour[held]
    out = image.copy()
    out[..., :3] = np.clip(np.round(matched * 255.0), 0, 255).astype(np.uint8) if integer else matched.astype(image.dtype)
    return out


# Where the capture keeps the exposures estimated from the backgrounds (exposure_estimate.py).
ESTIMATED_EXPOSURE_KEY = "estimated_exposure"


def estimate_record(found) -> dict:
    """An ExposureEstimate as the capture keeps it (JSON), with whether each part is matched."""
    return {"stops": {f: round(s, 3) for f, s in found.stops.items()}, "pairs": found.pairs,
            "residual_stops": round(found.residual_stops, 3), "matched": found.worth_matching,
            "colour_stops": {f: [round(v, 4) for v in c] for f, c in found.colour_stops.items()},
            "colour_matched": found.colour_worth_matching}


def matching_gains(exif_stops: Mapping[str, float | None], estimated: dict | None) -> dict[str, np.ndarray] | None:
    """Per frame, the gain on each of its red, green, blue that brings it to the shoot's exposure and
    white balance: the exposure from `exif_stops` when every photo has one, else from the backgrounds'
    estimate (`estimated`, an `estimate_record`) when it is matched; the balance from the estimate when
    it is matched, scaled to leave a grey's luminance as it was (so a balanced channel may come out a
    little darker: `match_exposure` keeps its clipped pixels clipped). None when there is nothing to match."""
    estimated = estimated or {}
    if exif_stops and all(s is not None for s in exif_stops.values()):
        exposure = exposure_gains(exif_stops)
    elif estimated.get("matched"):
        exposure = exposure_gains({f: float(v) for f, v in estimated["stops"].items()}, ESTIMATE_NOISE_STOPS)
    else:
        exposure = None
    colour = None
    if estimated.get("colour_matched"):
        colour = {}
        for f, offset in estimated["colour_stops"].items():
            gain = 2.0 ** -np.asarray(offset, np.float64)
            colour[f] = gain / float(gain @ _LUMINANCE)
    if exposure is None and colour is None:
        return None
    frames = set(exposure or {}) | set(colour or {})
    return {f: (exposure or {}).get(f, 1.0) * (colour or {}).get(f, np.ones(3)) for f in sorted(frames)}


def capture_exposure_gains(capture) -> dict[str, np.ndarray] | None:
    """`matching_gains` of a capture's frames: their EXIF exposures, and what the lighting stage
    estimated from the photos' shared backgrounds (kept in the capture's settings)."""
    exif = {frame_id: state.record.exposure_stops for frame_id, state in capture.frames.items()}
    return matching_gains(exif, capture.settings.get(ESTIMATED_EXPOSURE_KEY))


def estimated_exposure_note(capture) -> tuple[str, bool] | None:
    """What the capture report (and the app, after an import) says of the exposures the backgrounds
    gave (exposure_estimate.py): the sentence, and whether it is a warning (the exposure moved more
    than exif_exposure.WARN_SPREAD_STOPS); None when EXIF told every exposure or nothing was estimated."""
    from .exif_exposure import WARN_SPREAD_STOPS  # (exif_exposure imports this module)

    estimated = capture.settings.get(ESTIMATED_EXPOSURE_KEY)
    if not estimated or all(state.record.exposure_stops is not None for state in capture.frames.values()):
        return None
    found = estimated["stops"]
    spread = max(found.values()) - min(found.values())
    text = f"{len(found)} photos, {spread:.1f} EV between the brightest and darkest exposed"
    if not estimated.get("matched") and estimated.get("residual_stops", 0.0) > MAX_RESIDUAL_STOPS:
        return text + (f", but the photos' backgrounds disagree with each other by {estimated['residual_stops']:.2f} EV "
                       f"(more than {MAX_RESIDUAL_STOPS}: surroundings too near or patterned to compare), so nothing "
                       "was matched"), False
    if spread <= ESTIMATE_NOISE_STOPS:
        return text + f" (within the estimate's own {ESTIMATE_NOISE_STOPS} EV: one exposure, nothing matched)", False
    text += "; the working copies are matched to the most exposed photo (the others brightened in linear light)"
    warn = spread > WARN_SPREAD_STOPS
    if warn:
        text += (", which leaves a phone's own tone mapping and the highlights the brightening clips: lock the exposure "
                 "when shooting (on a phone, press and hold on the object to lock AE/AF) or use manual exposure")
    return text, warn


def white_balance_note(capture) -> tuple[str, bool] | None:
    """What the capture report (and the app, after an import) says of the photos' white balance as
    their shared backgrounds gave it (exposure_estimate.py), and whether the working copies were
    balanced for it; None when nothing was estimated, or when the backgrounds disagree (nothing was
    matched by them, and the estimate says why)."""
    estimated = capture.settings.get(ESTIMATED_EXPOSURE_KEY)
    if not estimated or not estimated.get("colour_stops") or estimated.get("residual_stops", 0.0) > MAX_RESIDUAL_STOPS:
        return None
    spread = colour_spread(estimated["colour_stops"])
    text = f"{len(estimated['colour_stops'])} photos, {100 * (2 ** spread - 1):.0f}% apart in one colour at most"
    if estimated.get("colour_matched"):
        return text + " (the camera balanced each shot on its own); the working copies are balanced as the shoot's average", True
    return text + f" (within the estimate's own {100 * (2 ** COLOUR_NOISE_STOPS - 1):.0f}%: one white balance, nothing matched)", False


def capture_response(capture) -> str:
    """The camera curve a capture's photos are read through: the one its lighting estimate chose (the
    latest "lighting" entry of its history), else the product's ACES curve."""
    for entry in reversed(capture.history):
        if entry.get("action") == "lighting" and entry.get("camera_response") in RESPONSES:
            return str(entry["camera_response"])
    return "aces"


def exposure_matched_image(capture, frame_id: str, gains: Mapping[str, np.ndarray] | None, response: str | None = None,
                           pinhole: bool = True) -> np.ndarray:
    """The capture's working image of `frame_id` (Capture.read_image) at the common exposure and white
    balance that `gains` (capture_exposure_gains; None: as stored) bring every photo to."""
    image = capture.read_image(frame_id, pinhole)
    if gains is None or frame_id not in gains:
        return image
    return match_exposure(image, gains[frame_id], response or capture_response(capture))
