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


def ssim(prediction: np.ndarray, target: np.ndarray, data_range: float = 1.0) -> float:
    """Mean structural similarity (Wang et al. 2004: 11x11 Gaussian window, sigma 1.5, K1 0.01,
    K2 0.03), over all pixels and channels of (H, W) or (H, W, C) images."""
    import cv2

    x = np.asarray(prediction, np.float64)
    y = np.asarray(target, np.float64)
    if x.shape != y.shape:
        raise ValueError(f"ssim: shapes differ, {x.shape} and {y.shape}")
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2

    def blur(a: np.ndarray) -> np.ndarray:
        return cv2.GaussianBlur(a, (11, 11), 1.5, borderType=cv2.BORDER_REFLECT)

    mx, my = blur(x), blur(y)
    vx, vy, cxy = blur(x * x) - mx * mx, blur(y * y) - my * my, blur(x * y) - mx * my
    ssim_map = ((2 * mx * my + c1) * (2 * cxy + c2)) / ((mx * mx + my * my + c1) * (vx + vy + c2))
    return float(ssim_map.mean())
