"""The lens's focal length from a photo's EXIF: a prior that COLMAP starts from and trusts.

Without it COLMAP starts every camera at 1.2 x the long side and marks the focal length as unknown,
so each pair of photos is verified with a fundamental matrix (no calibration) and the mapper may
only start from pairs whose focal it cannot check; with a prior it verifies pairs with an essential
matrix and refines the focal length from a sensible start. Phones and cameras write the focal
length in two ways, read in this order:

- FocalLengthIn35mmFilm (0xA405): the focal length a 36 x 24 mm film camera would need for the same
  field of view, measured on the diagonal (CIPA DC-008), so in pixels f = f35 / 43.27 mm x the
  image's diagonal in pixels. Every phone writes it.
- FocalLength (0x920A) with FocalPlaneXResolution (0xA20E, pixels per unit of the sensor at the
  full image size) and its unit (0xA210): f = focal mm x pixels per mm. Many interchangeable-lens
  cameras write only these.

Working copies are scaled (never cropped), so a focal length in pixels scales with the long side.
A value that gives a field of view outside 8-150 degrees on the long side is taken for a wrong tag
and ignored: the photo is then posed as it was before, without a prior.
"""

from __future__ import annotations

import math

import numpy as np
from PIL import Image

FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
EXIF_IFD = 0x8769
FOCAL_LENGTH = 0x920A
FOCAL_LENGTH_35MM = 0xA405
FOCAL_PLANE_X_RESOLUTION = 0xA20E
FOCAL_PLANE_RESOLUTION_UNIT = 0xA210
MM_PER_UNIT = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}  # inch, cm, mm, micrometre
PLAUSIBLE_FOV_DEG = (8.0, 150.0)
LENS_TOLERANCE = 0.1  # EXIF focal lengths this close (relative) are one lens


def focal_prior_pixels(image: Image.Image, stored_size: tuple[int, int], working_size: tuple[int, int]) -> float | None:
    """The focal length in pixels of the working copy (`working_size`, upright) of a photo whose
    stored pixels are `stored_size`, or None when its EXIF does not say or says something implausible."""
    try:
        exif = image.getexif().get_ifd(EXIF_IFD)
    except Exception:  # damaged EXIF costs the prior, never the photo
        return None
    width, height = working_size
    focal = None
    f35 = _positive(exif.get(FOCAL_LENGTH_35MM))
    if f35 is not None:
        focal = f35 / FULL_FRAME_DIAGONAL_MM * math.hypot(width, height)
    else:
        focal_mm = _positive(exif.get(FOCAL_LENGTH))
        per_unit = _positive(exif.get(FOCAL_PLANE_X_RESOLUTION))
        unit_mm = MM_PER_UNIT.get(int(exif.get(FOCAL_PLANE_RESOLUTION_UNIT, 2) or 2))
        if focal_mm is not None and per_unit is not None and unit_mm is not None:
            focal = focal_mm * per_unit / unit_mm * max(width, height) / max(stored_size)
    if focal is None:
        return None
    fov = math.degrees(2.0 * math.atan(max(width, height) / (2.0 * focal)))
    return focal if PLAUSIBLE_FOV_DEG[0] <= fov <= PLAUSIBLE_FOV_DEG[1] else None


def split_by_lens(items, focal_of=lambda focal: focal) -> list[list]:
    """`items` in increasing focal length, split into lenses: a new lens wherever one is more than
    LENS_TOLERANCE above its lens's first (a phone's 2x camera; a zoom moved less is one lens)."""
    lenses: list[list] = []
    for item in sorted(items, key=focal_of):
        if lenses and focal_of(item) <= focal_of(lenses[-1][0]) * (1 + LENS_TOLERANCE):
            lenses[-1].append(item)
        else:
            lenses.append([item])
    return lenses


def shared_focal_prior(records, tolerance: float = 0.02) -> float | None:
    """The photos' common EXIF focal length (pixels), or None when any lacks one or they disagree
    (a zoom lens moved): one COLMAP camera per image size cannot take two focal lengths."""
    focals = [r.focal_prior_px for r in records]
    if not focals or any(f is None for f in focals):
        return None
    middle = float(np.median(focals))
    return middle if all(abs(f - middle) <= tolerance * middle for f in focals) else None


def _positive(value) -> float | None:
    try:
        number = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return number if math.isfinite(number) and number > 0 else None
