"""Photos in another colour space than sRGB, converted to sRGB at ingest.

Everything after ingest reads a working copy as sRGB (DESIGN.md's colour convention: the masks, the
lighting estimate from the backgrounds, the network, the materials the refinement fits). Phones do
not all shoot sRGB: iPhones have written Display P3 JPEGs and HEICs since 2016, and photos exported
from an editor may be Adobe RGB. Their pixel values read as sRGB come out less saturated than the
scene (a P3 orange read as sRGB is duller), and the fitted albedo with them. A photo whose embedded
ICC profile is not sRGB is converted to sRGB through it (littlecms, relative colorimetric: colours
inside sRGB keep their values, those outside are clipped to its gamut, as a display would).
A profile that cannot be read leaves the photo as stored: a colour cast is better than losing it.
"""

from __future__ import annotations

import io

import numpy as np
from PIL import Image, ImageCms

_SRGB = None


def _srgb_profile():
    global _SRGB
    if _SRGB is None:
        _SRGB = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))
    return _SRGB


def embedded_profile(image: Image.Image) -> ImageCms.ImageCmsProfile | None:
    """The photo's ICC profile when it describes an RGB space other than sRGB, else None."""
    data = image.info.get("icc_profile")
    if not data:
        return None
    try:
        profile = ImageCms.ImageCmsProfile(io.BytesIO(data))
        description = ImageCms.getProfileDescription(profile) or ""
        space = profile.profile.xcolor_space.strip()
    except Exception:  # a damaged profile: the photo stays as stored
        return None
    if space != "RGB" or "srgb" in description.lower().replace(" ", ""):
        return None
    return profile


def to_srgb(pixels: np.ndarray, profile: ImageCms.ImageCmsProfile | None) -> np.ndarray:
    """8-bit RGB or RGBA `pixels` encoded in `profile`'s space -> the same picture encoded in sRGB
    (alpha untouched); `pixels` unchanged without a profile or when the conversion fails."""
    if profile is None or pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
        return pixels
    try:
        converted = ImageCms.profileToProfile(Image.fromarray(np.ascontiguousarray(pixels[:, :, :3])), profile, _srgb_profile(),
                                              renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC, outputMode="RGB")
    except Exception:  # littlecms refused the profile (a malformed one can pass the reading above)
        return pixels
    rgb = np.asarray(converted)
    return np.ascontiguousarray(np.concatenate([rgb, pixels[:, :, 3:]], axis=2) if pixels.shape[2] == 4 else rgb)
