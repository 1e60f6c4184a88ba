"""From a photo's display values back to scene radiance: the camera's tone curve, inverted.

A photo is display-referred sRGB (DESIGN.md §3), and a camera's JPEG engine also compresses
highlights with a filmic S-curve that a plain sRGB decode leaves in. With no way to calibrate a
user's camera from a handful of photos, the product models every camera with its own display
transform (renderer/tonemap.py: ACES fit, then sRGB): the inverse of what the viewport shows. Then an
asset lit "as photographed" and shown in the viewport reproduces the photos' tones, and the
synthetic shoots (rendered through that transform) invert exactly. "srgb" is the plain decode, for
photos known to be linear before their sRGB encoding.
"""

from __future__ import annotations

import numpy as np

from lirm.renderer.tonemap import ACES_INPUT, ACES_OUTPUT

RESPONSES = ("aces", "srgb")
# The renderer's tone mapper (RenderSettings.tonemapper) that is each response's forward curve.
TONE_CURVE_OF_RESPONSE = {"aces": "aces", "srgb": "linear"}
# The ACES fit's rational curve reaches 1 / 0.983729 only at infinite radiance; display values are
# capped just below 1 (a clipped pixel), which inverts to a finite radiance: the lower bound of
# what the pixel saw.
_CURVE_CAP = 0.999 / 0.983729


def display_to_radiance(display: np.ndarray, response: str = "aces") -> np.ndarray:
    """(..., 3) display sRGB in [0, 1] -> linear scene radiance (exposure 0), in float64."""
    import torch

    return display_to_radiance_torch(torch.from_numpy(np.asarray(display, np.float64)), response).numpy()


def radiance_to_display(radiance: np.ndarray, response: str = "aces") -> np.ndarray:
    """(..., 3) linear scene radiance -> display sRGB in [0, 1], in float64 (`radiance_to_display_torch`
    on numpy arrays)."""
    import torch

    return radiance_to_display_torch(torch.from_numpy(np.asarray(radiance, np.float64)), response).numpy()


def display_to_radiance_torch(display, response: str = "aces"):
    """(..., 3) display sRGB in [0, 1] -> linear scene radiance (exposure 0); the one implementation
    (`display_to_radiance` is it on numpy arrays). No gradient is needed through it: it makes targets."""
    import torch

    if response not in RESPONSES:
        raise ValueError(f"unknown camera response {response!r}; choose one of {', '.join(RESPONSES)}")
    d = display.clamp(0.0, 1.0)
    linear = torch.where(d <= 0.04045, d / 12.92, ((d + 0.055) / 1.055) ** 2.4)
    if response == "srgb":
        return linear
    out_inverse = torch.as_tensor(np.linalg.inv(ACES_OUTPUT), dtype=d.dtype, device=d.device)
    in_inverse = torch.as_tensor(np.linalg.inv(ACES_INPUT), dtype=d.dtype, device=d.device)
    y = (linear @ out_inverse.T).clamp(0.0, _CURVE_CAP)
    # Solve v (v + 0.0245786) - 0.000090537 = y (0.983729 v^2 + 0.4329510 v + 0.238081) for v >= 0.
    a = 1.0 - 0.983729 * y
    b = 0.0245786 - 0.4329510 * y
    c = -(0.000090537 + 0.238081 * y)
    v = (-b + (b * b - 4.0 * a * c).clamp(min=0.0).sqrt()) / (2.0 * a)
    return (v @ in_inverse.T).clamp(min=0.0)


def radiance_to_display_torch(radiance, response: str = "aces"):
    """Differentiable forward of the camera model (renderer/tonemap.py's `tonemap` at exposure 0):
    linear radiance (..., 3) -> display sRGB in [0, 1]."""
    import torch

    if response not in RESPONSES:
        raise ValueError(f"unknown camera response {response!r}; choose one of {', '.join(RESPONSES)}")
    c = radiance.clamp(min=0.0)
    if response == "aces":
        m_in = torch.as_tensor(ACES_INPUT, dtype=c.dtype, device=c.device)
        m_out = torch.as_tensor(ACES_OUTPUT, dtype=c.dtype, device=c.device)
        v = c @ m_in.T
        a = v * (v + 0.0245786) - 0.000090537
        b = v * (0.983729 * v + 0.4329510) + 0.238081
        c = (a / b) @ m_out.T
    c = c.clamp(0.0, 1.0)
    return torch.where(c <= 0.0031308, 12.92 * c, 1.055 * c.clamp(min=0.0031308) ** (1.0 / 2.4) - 0.055)


# A plain backdrop clipped in at least this share of the directions the photos saw it in makes the
# capture's camera plain sRGB (`response_for_capture`).
CLIPPED_BACKDROP_SHARE = 0.5


def response_for_capture(requested: str, plain_backdrop: bool, clipped_share: float) -> tuple[str, str]:
    """The tone curve a capture's photos are read through, and why (for the report).

    "auto" is the product's ACES curve, except for a plain backdrop photographed clipped: a white
    sweep or lightbox exposed to pure white, the usual product shot. Through the ACES curve a pixel at
    250/255 is 7 times the radiance of one at 200/255 and at 255/255 26 times, so such a backdrop
    reads as a light of 7-26 around an object of about 1, and the refinement explains the object's
    colour with a dark albedo under it (the lego's 50 photos on white: its yellow and grey came out
    brown and black, the plate metallic and fully rough). A camera's JPEG curve rolls its highlights
    off far more gently than the ACES fit, and the backdrop is often lit apart and over-exposed on
    purpose, so there the plain sRGB decode is the nearer model (the backdrop reads as 1)."""
    if requested in RESPONSES:
        return requested, "as asked"
    if requested != "auto":
        raise ValueError(f"unknown camera response {requested!r}; choose auto or one of {', '.join(RESPONSES)}")
    if plain_backdrop and clipped_share >= CLIPPED_BACKDROP_SHARE:
        return "srgb", (f"a plain backdrop clipped in {100 * clipped_share:.0f}% of what the photos saw: read as a "
                        "camera's plain sRGB, not the ACES curve")
    return "aces", "the product's display transform (ACES)"
