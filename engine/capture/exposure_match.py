"""Photos exposed apart, brought to one exposure before anything compares them.

A phone exposes every shot on its own: walking round an object with a window on one side moves the
exposure by a stop or more between shots, and everything after ingest (the lighting from the
backgrounds, LIRM's inputs, the refinement's photometric terms, the export's texture fit, the held-out
views) compares a pixel of one photo with a pixel of another as the same radiance. The EXIF says how
each was exposed (exif_exposure.py: stops = log2(time x ISO / 100 / f-number^2)), so each photo's
linear radiance can be scaled to a common exposure: through the capture's camera curve to linear
light, times 2^(reference - stops), and back.

The reference is the most exposed photo, so every other photo is brightened, never darkened: a
pixel the camera clipped stays clipped (the lighting estimate and the texture fit read a clipped value
as "at least this bright"); darkening would turn it into a plain value and lose that. What it cannot
undo: highlights a darker shot held and the brightening clips, a phone's local tone mapping that
differs between shots, and photos of several cameras (their sensitivities differ for the same ISO).

Only the working copies made for the reconstruction change (the crops, the images the lighting is
estimated from); the photos and the capture's working images stay as they were taken.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from lirm.engine.lighting.camera_response import RESPONSES, display_to_radiance, radiance_to_display

# Exposures this close are the same: EXIF rounds a shutter time (1/60 written for 1/64 is 0.09 EV).
SAME_EXPOSURE_STOPS = 0.1


def exposure_gains(stops: Mapping[str, float | None]) -> dict[str, float] | None:
    """Per frame, the factor on its linear radiance that makes it as exposed as the most exposed
    frame: 2^(max - stops), 1 for that frame. None when the photos need no matching (all within
    `SAME_EXPOSURE_STOPS`) or cannot be matched (a frame without EXIF exposure: its place is unknown)."""
    if len(stops) < 2 or any(s is None for s in stops.values()):
        return None
    most = max(stops.values())
    if most - min(stops.values()) <= SAME_EXPOSURE_STOPS:
        return None
    return {frame: float(2.0 ** (most - s)) for frame, s in stops.items()}


def match_exposure(image: np.ndarray, gain: float, response: str) -> np.ndarray:
    """`image` (H, W, 3 or 4; uint8, or float display values in [0, 1]) with its linear radiance
    multiplied by `gain` through the camera curve `response` (camera_response.RESPONSES); the same
    dtype, an alpha channel untouched. A gain of 1 returns the image itself."""
    if gain == 1.0:
        return image
    if not gain > 0 or not np.isfinite(gain):
        raise ValueError(f"an exposure gain must be a positive number, got {gain}")
    if response not in RESPONSES:
        raise ValueError(f"unknown camera response {response!r}; choose one of {', '.join(RESPONSES)}")
    integer = image.dtype == np.uint8
    colour = image[..., :3].astype(np.float64) / 255.0 if integer else np.asarray(image[..., :3], np.float64)
    matched = radiance_to_display(display_to_radiance(colour, response) * gain, response)
    out = image.copy()
    out[..., :3] = np.clip(np.round(matched * 255.0), 0, 255).astype(np.uint8) if integer else matched.astype(image.dtype)
    return out


def capture_exposure_gains(capture) -> dict[str, float] | None:
    """`exposure_gains` of every frame of a capture (its records' EXIF exposures)."""
    return exposure_gains({frame_id: state.record.exposure_stops for frame_id, state in capture.frames.items()})


def capture_response(capture) -> str:
    """The camera curve a capture's photos are read through: the one its lighting estimate chose (the
    latest "lighting" entry of its history), else the product's ACES curve."""
    for entry in reversed(capture.history):
        if entry.get("action") == "lighting" and entry.get("camera_response") in RESPONSES:
            return str(entry["camera_response"])
    return "aces"


def exposure_matched_image(capture, frame_id: str, gains: Mapping[str, float] | None, response: str | None = None,
                           pinhole: bool = True) -> np.ndarray:
    """The capture's working image of `frame_id` (Capture.read_image) at the common exposure that
    `gains` (capture_exposure_gains; None: as stored) bring every photo to."""
    image = capture.read_image(frame_id, pinhole)
    if gains is None or frame_id not in gains:
        return image
    return match_exposure(image, gains[frame_id], response or capture_response(capture))
