"""Image metrics shared by benchmarks and evaluation (numpy, images in [0, 1])."""

from __future__ import annotations

import numpy as np


def psnr(prediction: np.ndarray, target: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Peak signal-to-noise ratio in dB for values in [0, 1]; over `mask`'s pixels if given."""
    err = (np.asarray(prediction, np.float64) - np.asarray(target, np.float64)) ** 2
    if mask is not None:
        err = err[np.asarray(mask, bool)]
    mse = float(err.mean()) if err.size else 0.0
    return float("inf") if mse == 0 else float(-10.0 * np.log10(mse))


def scaled_albedo_psnr(prediction: np.ndarray, target: np.ndarray, mask: np.ndarray) -> float:
    """Albedo PSNR after the per-channel least-squares scale of Stanford-ORB (albedo is only known
    up to the lighting's scale), on the object's pixels."""
    m = np.asarray(mask, bool)
    p, t = np.asarray(prediction, np.float64)[m], np.asarray(target, np.float64)[m]
    scale = (p * t).sum(axis=0) / np.maximum((p * p).sum(axis=0), 1e-12)
    return psnr(np.clip(p * scale, 0.0, 1.0), t)
