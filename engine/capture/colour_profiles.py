"""Photos in another colour space than sRGB, converted to sRGB at ingest.

Everything after ingest reads a working copy as sRGB (DESIGN.md's colour convention: the masks, the
lighting estimate from the backgrounds, the network, the materials the refinement fits). Phones do
not all shoot sRGB: iPhones have written Display P3 JPEGs and HEICs since 2016, and photos exported
from an editor may be Adobe RGB. Their pixel values read as sRGB come out less saturated than the
scene (a P3 orange read as sRGB is duller), and the fitted albedo with them. A photo whose embedded
ICC profile is not sRGB is converted to sRGB through it (littlecms, relative colorimetric: colours
inside sRGB keep their values, those outside are clipped to its gamut, as a display would).
A profile that cannot be read leaves the photo as stored: a colour cast is better than losing it.

HEIC / HEIF files may describe their colours without an ICC profile, by the codes of ITU-T H.273
(an "nclx" box: primaries, transfer curve). Android phones' HEICs and Apple's own encoder write
Display P3 so (primaries 12, the sRGB curve 13). Those are converted in numpy: the transfer curve
undone, the primaries' RGB -> XYZ (white points adapted by Bradford when they differ from D65)
-> sRGB, clipped to its gamut as the ICC path's relative intent does, the sRGB curve applied. The
curves of BT.709 and its kin (1, 6, 14, 15) are read as sRGB's, as still-image software does. An
HDR curve (PQ, HLG) or an unknown one leaves the photo as stored: it needs tone mapping, not a
change of primaries, and an sRGB reading of it is what the photo looked like before this version.
"""

from __future__ import annotations

import io
from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageCms

_SRGB = None


def _srgb_profile():
    global _SRGB
    if _SRGB is None:
        _SRGB = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))
    return _SRGB


# sRGB's (and BT.709's) primaries and D65 white, as xy chromaticities.
SRGB_PRIMARIES = ((0.640, 0.330), (0.300, 0.600), (0.150, 0.060), (0.3127, 0.3290))
# H.273 transfer codes whose curve is read as sRGB's: 13 is sRGB; 1, 6, 14 and 15 are BT.709's camera
# curve, which still-image software shows as sRGB. Plain powers: 4 (2.2), 5 (2.8); 8 is linear.
_SRGB_LIKE_TRANSFERS = (1, 6, 13, 14, 15)
_GAMMA_TRANSFERS = {4: 2.2, 5: 2.8, 8: 1.0}
_BRADFORD = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])


@dataclass(frozen=True)
class NclxSpace:
    """A HEIF's colours as H.273 codes: the primaries' and white's xy, and the transfer code."""

    primaries: tuple[tuple[float, float], ...]  # red, green, blue, white
    transfer: int

    def rgb_to_srgb_matrix(self) -> np.ndarray:
        """Linear RGB in these primaries -> linear sRGB (Bradford-adapted to D65 when the white differs)."""
        source = _rgb_to_xyz(self.primaries)
        target = _rgb_to_xyz(SRGB_PRIMARIES)
        white_in, white_out = _xy_to_xyz(*self.primaries[3]), _xy_to_xyz(*SRGB_PRIMARIES[3])
        cone_scale = (_BRADFORD @ white_out) / (_BRADFORD @ white_in)
        adapt = np.linalg.inv(_BRADFORD) @ np.diag(cone_scale) @ _BRADFORD
        return np.linalg.inv(target) @ adapt @ source


def _xy_to_xyz(x: float, y: float) -> np.ndarray:
    return np.array([x / y, 1.0, (1.0 - x - y) / y])


def _rgb_to_xyz(primaries) -> np.ndarray:
    """Columns: each primary's XYZ, scaled so that full red + green + blue is the white (Y = 1)."""
    m = np.stack([_xy_to_xyz(*p) for p in primaries[:3]], axis=1)
    return m * np.linalg.solve(m, _xy_to_xyz(*primaries[3]))


def _srgb_decode(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _srgb_encode(v: np.ndarray) -> np.ndarray:
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * np.power(np.maximum(v, 0.0031308), 1 / 2.4) - 0.055)


def nclx_space(image: Image.Image) -> NclxSpace | None:
    """A HEIF's nclx colour description when it names primaries other than sRGB's with a curve that
    can be undone here, else None (sRGB, unspecified, HDR curves, or none given)."""
    nclx = image.info.get("nclx_profile")
    if not isinstance(nclx, dict):
        return None
    try:
        code, transfer = int(nclx.get("color_primaries", 2)), int(nclx.get("transfer_characteristics", 2))
        if code in (1, 2) or (transfer not in _SRGB_LIKE_TRANSFERS and transfer not in _GAMMA_TRANSFERS):
            return None
        keys = ("red", "green", "blue", "white")
        xy = tuple((float(nclx[f"color_primary_{k}_x"]), float(nclx[f"color_primary_{k}_y"])) for k in keys)
    except (KeyError, TypeError, ValueError):  # a damaged description: the photo stays as stored
        return None
    if not all(0.0 < x < 1.0 and 0.0 < y < 1.0 for x, y in xy) or np.allclose(xy, SRGB_PRIMARIES, atol=2e-3):
        return None
    return NclxSpace(xy, transfer)


def source_colour_space(image: Image.Image) -> ImageCms.ImageCmsProfile | NclxSpace | None:
    """What the photo's pixels are encoded in when it is not sRGB: its ICC profile, else a HEIF's
    nclx description, else None (sRGB, or untagged, which is read as sRGB). An ICC profile, when
    there is one, is what the file's colours are (HEIF allows both; the profile is the exact one)."""
    if image.info.get("icc_profile"):
        return embedded_profile(image)
    return nclx_space(image)


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


def _nclx_to_srgb(rgb: np.ndarray, space: NclxSpace) -> np.ndarray:
    levels = np.arange(256, dtype=np.float64) / 255.0  # the curve undone once per 8-bit level
    gamma = _GAMMA_TRANSFERS.get(space.transfer)
    linear_of_level = _srgb_decode(levels) if gamma is None else levels ** gamma
    linear = linear_of_level[rgb].reshape(-1, 3) @ space.rgb_to_srgb_matrix().T
    encoded = _srgb_encode(np.clip(linear, 0.0, 1.0))
    return np.clip(np.rint(encoded * 255.0), 0, 255).astype(np.uint8).reshape(rgb.shape)


def to_srgb(pixels: np.ndarray, profile: ImageCms.ImageCmsProfile | NclxSpace | None) -> np.ndarray:
    """8-bit RGB or RGBA `pixels` encoded in `profile`'s space (an ICC profile or a HEIF's nclx
    description) -> the same picture encoded in sRGB (alpha untouched); `pixels` unchanged without a
    profile or when the conversion fails."""
    if profile is None or pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
        return pixels
    if isinstance(profile, NclxSpace):
        rgb = _nclx_to_srgb(np.ascontiguousarray(pixels[:, :, :3]), profile)
        return np.ascontiguousarray(np.concatenate([rgb, pixels[:, :, 3:]], axis=2) if pixels.shape[2] == 4 else rgb)
    try:
        converted = ImageCms.profileToProfile(Image.fromarray(np.ascontiguousarray(pixels[:, :, :3])), profile, _srgb_profile(),
                                              renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC, outputMode="RGB")
    except Exception:  # littlecms refused the profile (a malformed one can pass the reading above)
        return pixels
    rgb = np.asarray(converted)
    return np.ascontiguousarray(np.concatenate([rgb, pixels[:, :, 3:]], axis=2) if pixels.shape[2] == 4 else rgb)
