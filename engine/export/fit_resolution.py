"""Fitting the textures at the photos' own resolution, whatever size the export's textures are.

The texture fit pulls each texel toward the photo pixels whose sub-samples land on it. When the
export's texture is much finer than the photos (the default 1024 px texture against 128-256 px crops),
a photo pixel spans many texels but its few sub-samples pull only the four nearest each: the fitted
texels form a sparse speckle over the baked ones, and the renderer's mipmaps, which average a pixel's
whole footprint, mix the two. Measured on four saved synthetic fields (128 px inputs): the same fit
relit 23.79 dB PSNR-L at 1024 px against 24.92 at 256 px (README, "The texture fit at the photos'
resolution").

So the fit runs at the largest size (the export's halved, power-of-two steps, not below 64) at which
a photo pixel spans at most `max_texels_per_pixel` texels on the median, on the baked textures
averaged down to it; its change to them is carried back up to the export's size (bilinear, as the
renderer magnifies) and added to the baked textures there, so that the baked detail finer than the
photos stays and the normal map keeps its full size.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from .texture_bake import BakedTextures, dilate

MIN_FIT_SIZE = 64


def texels_per_photo_pixel(uv: torch.Tensor, footprint: int, size: int) -> float:
    """Median side of a photo pixel, in texels of a `size` texture: from the distance in the atlas
    between each pixel's first sub-sample and its neighbours one sub-sample across and one down
    (`footprint` = k*k sub-samples a pixel, row-major, 1/k pixel apart). NaN with one sub-sample."""
    k = int(round(footprint ** 0.5))
    if k < 2 or uv.shape[0] < footprint:
        return float("nan")
    rows = uv.reshape(-1, footprint, 2)
    across = (rows[:, 1] - rows[:, 0]).norm(dim=-1)
    down = (rows[:, k] - rows[:, 0]).norm(dim=-1)
    side = (across * down).sqrt() * k * size
    return float(side.median())


def fit_size_for(texels_per_pixel: float, size: int, max_texels_per_pixel: float, fixed: int | None = None) -> int:
    """The size to fit a `size` texture at, whose photo pixels span `texels_per_pixel` texels of it
    (texels_per_photo_pixel): `fixed` when given (at most `size`, and only a power-of-two division of
    it), else the largest halving of `size` (down to MIN_FIT_SIZE) at which a photo pixel spans at most
    `max_texels_per_pixel` texels. `size` itself when it cannot be halved evenly or the photos' pixels
    could not be measured (NaN: one sub-sample a pixel)."""
    candidates = [size]
    while candidates[-1] % 2 == 0 and candidates[-1] // 2 >= MIN_FIT_SIZE:
        candidates.append(candidates[-1] // 2)
    if fixed is not None:
        return fixed if fixed in candidates else size
    if not np.isfinite(texels_per_pixel) or texels_per_pixel <= 0:
        return size
    for candidate in candidates:
        if texels_per_pixel * candidate / size <= max_texels_per_pixel:
            return candidate
    return candidates[-1]


def averaged_down(textures: BakedTextures, size: int) -> BakedTextures:
    """The textures at `size` (a division of theirs): each coarse texel the mean of the covered fine
    texels under it (covered where any is); the normal map averaged and normalised."""
    f = textures.covered.shape[0] // size
    covered = textures.covered.astype(np.float32).reshape(size, f, size, f)
    weight = covered.sum(axis=(1, 3))

    def down(values: np.ndarray) -> np.ndarray:
        v = values.reshape(size, f, size, f, -1)
        summed = (v * covered[..., None]).sum(axis=(1, 3))
        plain = v.mean(axis=(1, 3))  # where nothing is covered: the dilated values, plainly averaged
        return np.where(weight[..., None] > 0, summed / np.maximum(weight, 1.0)[..., None], plain).astype(np.float32)

    normal = down(textures.normal)
    normal /= np.maximum(np.linalg.norm(normal, axis=-1, keepdims=True), 1e-12)
    return BakedTextures(down(textures.base_color), down(textures.roughness[..., None])[..., 0],
                         down(textures.metallic[..., None])[..., 0], normal, weight > 0)


def carried_up(full: BakedTextures, coarse: BakedTextures, fitted: BakedTextures, dilation: int) -> BakedTextures:
    """`full` (the baked textures at the export's size) plus the fit's change at the coarse size
    (`fitted` - `coarse`), grown into the uncovered coarse texels and magnified bilinearly."""
    size = full.covered.shape[0]

    def changed(base: np.ndarray, before: np.ndarray, after: np.ndarray) -> np.ndarray:
        delta = dilate((after - before).reshape(after.shape[:2] + (-1,)), coarse.covered, dilation)
        up = cv2.resize(delta, (size, size), interpolation=cv2.INTER_LINEAR).reshape(size, size, -1)
        return np.clip(base.reshape(size, size, -1) + up, 0.0, 1.0).astype(np.float32)

    return BakedTextures(changed(full.base_color, coarse.base_color, fitted.base_color),
                         changed(full.roughness, coarse.roughness, fitted.roughness)[..., 0],
                         changed(full.metallic, coarse.metallic, fitted.metallic)[..., 0],
                         full.normal, full.covered)
