"""The supplementary's schedule per preset, and the losses' substitutes for LPIPS."""

from __future__ import annotations

import pytest
import torch

from lirm.engine.train.perceptual import SSIMGradientLoss, lpips_available, perceptual_loss, ssim_map
from lirm.engine.train.stages import stage_config
from lirm.engine.train.trainer import inverse_beta, learning_rate


def test_paper_preset_is_the_supplementary_table():
    rows = [stage_config("paper", s) for s in (1, 2, 3)]
    assert [r.learning_rate for r in rows] == [(4e-4, 2e-5), (2e-5, 1e-6), (1e-6, 0.0)]
    assert [r.batch_scenes for r in rows] == [768, 320, 256]
    assert [r.samples_per_ray for r in rows] == [128, 512, 1024]
    assert [r.target_resolution for r in rows] == [256, 384, 512]
    assert [r.crop for r in rows] == [128, 128, 192]
    assert [r.inv_beta for r in rows] == [(10.0, 200.0), (200.0, 250.0), (250.0, 250.0)]
    assert [r.update_sets for r in rows] == [2, 3, 3]
    assert all(r.views_per_set == (3, 6) for r in rows)
    assert [r.occupancy_grid for r in rows] == [False, False, True]
    assert [r.numerical_normal_weight > 0 for r in rows] == [False, False, True]


def test_smaller_presets_keep_the_resolution_ratios():
    for name, size in (("small", 256), ("tiny", 64)):
        rows = [stage_config(name, s) for s in (1, 2, 3)]
        assert [r.target_resolution for r in rows] == [size // 2, size * 3 // 4, size]
        assert [r.crop for r in rows] == [size // 4, size // 4, size * 3 // 8]
    with pytest.raises(ValueError, match="stage must be 1, 2 or 3"):
        stage_config("tiny", 4)


def test_schedules_cosine_learning_rate_and_linear_inverse_beta():
    stage = stage_config("paper", 1, steps=1000, warmup_steps=100)
    assert learning_rate(stage, 0) == pytest.approx(4e-6)
    assert learning_rate(stage, 99) == pytest.approx(4e-4)
    assert learning_rate(stage, 550) == pytest.approx((4e-4 + 2e-5) / 2, rel=1e-3)
    assert learning_rate(stage, 999) == pytest.approx(2e-5, rel=1e-3)
    assert inverse_beta(stage, 0) == 10.0 and inverse_beta(stage, 999) == pytest.approx(200.0)
    assert inverse_beta(stage, 999 // 2) == pytest.approx(105.0, rel=0.01)


def test_substitute_perceptual_loss_is_zero_on_equal_images_and_differentiable():
    torch.manual_seed(0)
    x = torch.rand(2, 3, 32, 32)
    assert ssim_map(x, x).mean().item() == pytest.approx(1.0, abs=1e-5)
    loss = SSIMGradientLoss()
    assert loss(x, x).item() == pytest.approx(0.0, abs=1e-5)
    blurred = torch.nn.functional.avg_pool2d(x, 3, 1, 1)
    noisy = (x + 0.3 * torch.randn_like(x)).clamp(0, 1)
    assert loss(blurred, x).item() > 0.1 and loss(noisy, x).item() > 0.1
    y = x.clone().requires_grad_(True)
    loss(y, blurred).backward()
    assert torch.isfinite(y.grad).all() and y.grad.abs().sum() > 0


def test_lpips_is_used_only_when_it_can_run_here():
    ok, why = lpips_available()
    chosen = perceptual_loss()
    assert (chosen.name == "lpips-vgg") == ok
    if not ok:
        assert why and chosen.name == "ms-ssim+gradient"
