"""Tone mapping: exposure, the ACES filmic curve (Stephen Hill's fit) and sRGB encoding.

numpy reference of shaders/tonemap.frag (a test compares the two), and the sRGB conversions used at
the boundaries of the colour pipeline (DESIGN.md §3).
"""

from __future__ import annotations

import numpy as np

ACES_INPUT = np.array([[0.59719, 0.35458, 0.04823], [0.07600, 0.90834, 0.01566], [0.02840, 0.13383, 0.83777]])
ACES_OUTPUT = np.array([[1.60475, -0.53108, -0.07367], [-0.10208, 1.10813, -0.00605], [-0.00327, -0.07276, 1.07602]])
TONEMAPPERS = ("aces", "linear")


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(np.maximum(c, 0.0031308), 1.0 / 2.4) - 0.055)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, np.power((np.maximum(c, 0.04045) + 0.055) / 1.055, 2.4))


def aces_fit(rgb: np.ndarray) -> np.ndarray:
    v = rgb @ ACES_INPUT.T
    a = v * (v + 0.0245786) - 0.000090537
    b = v * (0.983729 * v + 0.4329510) + 0.238081
    return (a / b) @ ACES_OUTPUT.T


def tonemap(radiance: np.ndarray, exposure_ev: float = 0.0, tonemapper: str = "aces") -> np.ndarray:
    """Linear HDR (..., 3) -> display sRGB in [0, 1]."""
    if tonemapper not in TONEMAPPERS:
        raise ValueError(f"unknown tone mapper {tonemapper!r}; choose one of {', '.join(TONEMAPPERS)}")
    c = np.maximum(np.asarray(radiance, dtype=np.float64) * 2.0**exposure_ev, 0.0)
    if tonemapper == "aces":
        c = aces_fit(c)
    return linear_to_srgb(np.clip(c, 0.0, 1.0))
