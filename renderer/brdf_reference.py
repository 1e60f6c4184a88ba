"""Numpy reference of the GGX-Smith BRDF, for tests that hold the GPU integrators to account.

Uses uniform hemisphere sampling (a different estimator from the shaders' GGX importance sampling)
so that an error in the importance-sampling weights cannot hide in both.
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


def split_sum_terms(n_dot_v: float, roughness: float, samples: int = 400_000, seed: int = 0) -> tuple[float, float]:
    """(A, B) with directional albedo = F0 * A + B, by uniform hemisphere Monte Carlo."""
    rng = np.random.default_rng(seed)
    alpha = roughness * roughness
    # Stratified uniform hemisphere: cos(theta) uniform in [0, 1], pdf = 1 / (2 pi).
    u1 = (np.arange(samples) + rng.random(samples)) / samples
    u2 = rng.random(samples)
    cos_t = u1
    sin_t = np.sqrt(1.0 - cos_t**2)
    phi = 2.0 * np.pi * u2
    l = np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], axis=1)
    v = np.array([np.sqrt(1.0 - n_dot_v**2), 0.0, n_dot_v])
    h = l + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    n_dot_l = l[:, 2]
    f = ggx_distribution(h[:, 2], alpha) * smith_ggx_visibility(n_dot_v, n_dot_l, alpha)
    fc = (1.0 - np.clip(h @ v, 0.0, 1.0)) ** 5
    integrand = f * n_dot_l * 2.0 * np.pi
    return float(np.mean((1.0 - fc) * integrand)), float(np.mean(fc * integrand))
