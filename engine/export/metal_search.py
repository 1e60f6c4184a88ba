"""Which texels are metal: the per-texel choice between material hypotheses in the texture fit.

Why a search and not the gradient: a metal texel fitted as a dielectric (metallic near 0, where the
refinement's field usually leaves it) sits in a local minimum. Raising its metallic alone darkens its
diffuse colour before the albedo has moved to the metal's reflectance, so every small step costs
photometric error, and the quadratic prior that keeps the texture fit from scattering into noise
holds the metallic where the field left it anyway. Fitting the textures once per hypothesis instead
(the field's metallic as the prior says; metallic held at 0; metallic held at 1), each with its own
albedo and roughness, and keeping per texel the hypothesis whose shading explains the photo pixels
best, makes the jump the gradient cannot: a metal's coloured, view-dependent reflection and a
dielectric's steady diffuse colour under a white highlight differ across the views that see a texel.

A texel holds a few photo pixels at most, so the choice reads each hypothesis's photometric error
summed over a small neighbourhood of texels (a Gaussian in the atlas) and the field's own hypothesis
is kept unless another is clearly better (`margin`). Neighbourhoods may straddle the seams of the
atlas's charts; at a sigma of two texels that only blurs decisions at chart borders.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

AS_FITTED, DIELECTRIC, METAL = 0, 1, 2  # hypothesis indices, in the order the errors are given


@dataclass
class MetalChoice:
    choice: np.ndarray  # (S, S) int8: AS_FITTED, DIELECTRIC or METAL per texel

    def share(self, which: int, covered: np.ndarray) -> float:
        """Share of the covered texels that took hypothesis `which`."""
        return float((self.choice[covered] == which).mean()) if covered.any() else 0.0


def texel_of(uv: np.ndarray, size: int) -> np.ndarray:
    """(N, 2) glTF texture coordinates -> (N,) flat index of the texel each lands in (row = v, as the
    texture fit's lookups read the atlas)."""
    rows = np.clip((uv[:, 1] * size).astype(np.int64), 0, size - 1)
    cols = np.clip((uv[:, 0] * size).astype(np.int64), 0, size - 1)
    return rows * size + cols


def _neighbourhood_sum(values: np.ndarray, texels: np.ndarray, size: int, sigma: float) -> np.ndarray:
    total = np.bincount(texels, values.astype(np.float64), size * size).reshape(size, size)
    if sigma <= 0:
        return total
    k = 2 * int(np.ceil(3.0 * sigma)) + 1
    return cv2.GaussianBlur(total, (k, k), sigma, borderType=cv2.BORDER_CONSTANT)


def choose_hypotheses(errors: list[np.ndarray], uv: np.ndarray, size: int, sigma: float = 2.0, margin: float = 0.1,
                      min_pixels: float = 1.0) -> MetalChoice:
    """`errors`: per photo pixel, the photometric error of each hypothesis (AS_FITTED, DIELECTRIC,
    METAL), at the pixels' texture coordinates `uv`. Per texel, the hypothesis with the least error
    summed over a Gaussian neighbourhood of `sigma` texels; the as-fitted one's error is first scaled
    by (1 - `margin`), so another replaces it only when clearly better, and texels whose
    neighbourhood holds fewer than `min_pixels` photo pixels keep it."""
    if len(errors) != 3:
        raise ValueError(f"choose_hypotheses takes the errors of 3 hypotheses, got {len(errors)}")
    if not 0.0 <= margin < 1.0:
        raise ValueError(f"margin must lie in [0, 1), got {margin}")
    texels = texel_of(np.asarray(uv, np.float64), size)
    sums = np.stack([_neighbourhood_sum(np.asarray(e), texels, size, sigma) for e in errors])
    sums[AS_FITTED] *= 1.0 - margin
    pixels = _neighbourhood_sum(np.ones(len(texels)), texels, size, sigma)
    choice = np.argmin(sums, axis=0).astype(np.int8)
    choice[pixels < min_pixels] = AS_FITTED
    return MetalChoice(choice)
