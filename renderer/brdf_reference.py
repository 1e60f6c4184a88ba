"""Numpy reference of the GGX-Smith BRDF, for tests that hold the GPU integrators to account.

The integrators here are written out in full, without the algebraic shortcuts the shaders take, so
that a slip in a shader's weights cannot hide in both.
"""

from __future__ import annotations

import numpy as np


def ggx_distribution(n_dot_h: np.ndarray, alpha: float) -> np.ndarray:
    a2 = alpha * alpha
    f = n_dot_h * n_dot_h * (a2 - 1.0) + 1.0
    return a2 / (np.pi * f * f)


def smith_ggx_visibility(n_dot_v: np.ndarray, n_dot_l: np.ndarray, alpha: float) -> np.ndarray:
    a2 = alpha * alpha
    gv = n_dot_l * np.sqrt(n_dot_v * n_dot_v * (1.0 - a2) + a2)
    gl = n_dot_v * np.sqrt(n_dot_l * n_dot_l * (1.0 - a2) + a2)
    return 0.5 / np.maximum(gv + gl, 1e-30)


def split_sum_terms(n_dot_v: float, roughness: float, samples: int = 1_000_000, seed: int = 0) -> tuple[float, float]:
    """(A, B) with directional albedo = F0 * A + B, by Monte Carlo over GGX-distributed half vectors.

    Unlike the shader, nothing cancels analytically: the estimator evaluates the full BRDF
    D * V * F * cos and divides by the explicit pdf of the reflected direction, with a random
    stream instead of the shader's Hammersley points.
    """
    rng = np.random.default_rng(seed)
    alpha = max(roughness * roughness, 1e-4)
    xi1, xi2 = rng.random(samples), rng.random(samples)
    cos_h = np.sqrt((1.0 - xi1) / (1.0 + (alpha * alpha - 1.0) * xi1))
    sin_h = np.sqrt(np.maximum(0.0, 1.0 - cos_h**2))
    phi = 2.0 * np.pi * xi2
    h = np.stack([sin_h * np.cos(phi), sin_h * np.sin(phi), cos_h], axis=1)
    v = np.array([np.sqrt(max(0.0, 1.0 - n_dot_v**2)), 0.0, n_dot_v])
    v_dot_h = h @ v
    l = 2.0 * v_dot_h[:, None] * h - v
    n_dot_l = l[:, 2]
    ok = (n_dot_l > 0.0) & (v_dot_h > 0.0)
    d = ggx_distribution(cos_h, alpha)
    pdf_l = d * cos_h / (4.0 * np.maximum(v_dot_h, 1e-30))
    brdf_cos = d * smith_ggx_visibility(n_dot_v, np.maximum(n_dot_l, 0.0), alpha) * np.maximum(n_dot_l, 0.0)
    weight = np.where(ok, brdf_cos / np.maximum(pdf_l, 1e-30), 0.0)
    fc = (1.0 - np.clip(v_dot_h, 0.0, 1.0)) ** 5
    return float(np.mean((1.0 - fc) * weight)), float(np.mean(fc * weight))
