"""How each photo was exposed, from its EXIF: a phone's automatic exposure, named in the report.

Everything after ingest reads the photos as one exposure: the lighting from their backgrounds, the
refinement's photometric terms and the export's texture fit compare a pixel of one photo with a
pixel of another as the same radiance. A phone exposes every shot on its own, so walking round an
object with a window on one side changes the exposure between shots, and what one photo shows
brighter than another becomes the object's or the light's. The EXIF says by how much: a pixel's
value for a given radiance scales with exposure time x ISO / f-number^2, so

    stops = log2(exposure time [s] x ISO / 100 / f-number^2)

differs between two photos by the exposure difference in stops (EV). exposure_match.py brings the
working copies to one exposure by it; the capture report gives the spread and, above
`WARN_SPREAD_STOPS`, says to lock the exposure (what the matching cannot undo is named there).
"""

from __future__ import annotations

import io
import math
from typing import Sequence

from PIL import Image

from .exif_focal import EXIF_IFD
from .exposure_match import SAME_EXPOSURE_STOPS

EXPOSURE_TIME = 0x829A
F_NUMBER = 0x829D
ISO_SPEED = 0x8827  # PhotographicSensitivity (ISOSpeedRatings before EXIF 2.3); a number or a tuple
# Half a stop (1.41 x the brightness) is what a phone's exposure wanders by between shots of one scene
# without a change of light worth its name; more is the automatic exposure following the background.
WARN_SPREAD_STOPS = 0.5
_PLAUSIBLE = {"time": (1e-6, 120.0), "f_number": (0.5, 128.0), "iso": (1.0, 1e7)}


def _number(value) -> float | None:
    if isinstance(value, (tuple, list)):
        value = value[0] if value else None
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0 else None


def exposure_stops(image: Image.Image) -> float | None:
    """log2(exposure time x ISO / 100 / f-number^2) from the photo's EXIF, or None when a tag is
    missing or implausible (then the photo is simply not counted)."""
    try:
        exif = image.getexif().get_ifd(EXIF_IFD)
    except Exception:  # damaged EXIF costs the figure, never the photo
        return None
    values = {"time": _number(exif.get(EXPOSURE_TIME)), "f_number": _number(exif.get(F_NUMBER)), "iso": _number(exif.get(ISO_SPEED))}
    for key, (low, high) in _PLAUSIBLE.items():
        if values[key] is None or not low <= values[key] <= high:
            return None
    return math.log2(values["time"] * values["iso"] / 100.0 / values["f_number"] ** 2)


def exposure_stops_of_file(data: bytes) -> float | None:
    """`exposure_stops` of an encoded photo (only its header is read)."""
    try:
        return exposure_stops(Image.open(io.BytesIO(data)))
    except Exception:
        return None


def exposure_spread(stops: Sequence[float | None]) -> tuple[int, float] | None:
    """(photos with a figure, the largest difference between two of them in stops), or None when
    fewer than two photos have one."""
    known = [s for s in stops if s is not None]
    if len(known) < 2:
        return None
    return len(known), max(known) - min(known)


def exposure_note(stops: Sequence[float | None]) -> tuple[str, bool] | None:
    """What the capture report (and the app, after an import) says of the photos' exposures: the
    sentence, and whether it is a warning (a spread above `WARN_SPREAD_STOPS`); None without two
    photos whose EXIF tells."""
    spread = exposure_spread(stops)
    if spread is None:
        return None
    count, stops_apart = spread
    text = f"{count} of {len(stops)} photos, {stops_apart:.1f} EV between the brightest and darkest exposed"
    warn = stops_apart > WARN_SPREAD_STOPS
    if warn:
        text += f" (the camera's automatic exposure: {2 ** stops_apart:.1f} x in brightness)"
    if stops_apart <= SAME_EXPOSURE_STOPS:
        return text, warn
    if count < len(stops):  # exposure_match.exposure_gains: a photo of unknown exposure has no place to be matched to
        text += (f"; not matched by EXIF: {len(stops) - count} photo{'s say' if len(stops) - count > 1 else ' says'} "
                 "nothing of its exposure, so the capture estimates every photo's exposure from the backgrounds "
                 "they share instead (where the photos show their surroundings)")
    else:
        text += "; the working copies are matched to the most exposed photo (the others brightened in linear light)"
    if warn:
        text += (", which leaves a phone's own tone mapping and the highlights the brightening clips: lock the exposure "
                 "when shooting (on a phone, press and hold on the object to lock AE/AF) or use manual exposure")
    return text, warn
