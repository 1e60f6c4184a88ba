"""Image metrics against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.metrics import psnr, scaled_albedo_psnr, ssim


def test_psnr_closed_form_and_mask():
    a = np.zeros((8, 8, 3))
    assert psnr(a + 0.1, a) == pytest.approx(20.0)
    mask = np.zeros((8, 8), bool)
    mask[:4] = True
    b = a.copy()
    b[4:] = 1.0  # outside the mask: ignored
    assert psnr(b, a, mask) == float("inf")


def test_scaled_albedo_psnr_forgives_a_per_channel_scale():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.1, 0.8, (16, 16, 3))
    mask = np.ones((16, 16), bool)
    assert scaled_albedo_psnr(truth * np.array([0.5, 0.8, 1.2]), truth, mask) > 80
    assert scaled_albedo_psnr(truth[::-1], truth, mask) < 20


def test_ssim_constant_images_and_noise():
    a, b = 0.3, 0.6
    expected = (2 * a * b + 0.01**2) / (a * a + b * b + 0.01**2)  # variances vanish: only the luminance term
    assert ssim(np.full((32, 32), a), np.full((32, 32), b)) == pytest.approx(expected)
    rng = np.random.default_rng(1)
    image = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    assert ssim(image, image) == pytest.approx(1.0)
    noisy = np.clip(image + rng.normal(0, 0.1, image.shape), 0, 1)
    noisier = np.clip(image + rng.normal(0, 0.3, image.shape), 0, 1)
    assert 1.0 > ssim(noisy, image) > ssim(noisier, image) > 0.0
    assert ssim(noisy, image) == pytest.approx(ssim(image, noisy))
