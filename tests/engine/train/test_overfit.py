"""The capacity experiment's training loop, short: the loss falls when the tiny model trains on one
rendered object (the full experiment is `lirm bench capacity`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lirm.engine.synth.object_views import ObjectViewsConfig
from lirm.engine.train.overfit import OverfitConfig, learning_rate, render_training_views, run_overfit


def test_learning_rate_warms_up_and_decays():
    config = OverfitConfig(steps=100, warmup_steps=10)
    rates = [learning_rate(config, s) for s in range(100)]
    assert rates[0] < rates[9] == config.learning_rate and rates[-1] < 0.01 * config.learning_rate + config.final_learning_rate


def test_the_loss_falls_when_overfitting_one_object():
    config = replace(OverfitConfig(), views=ObjectViewsConfig(object_name="vase", size=32), steps=40, rays_per_step=512,
                     samples_per_ray=32, eval_every=0, eval_samples_per_ray=48, warmup_steps=5)
    views = render_training_views(config)
    assert views.image.shape == (4, 32, 32, 3) and 0.05 < views.mask.mean() < 0.5
    result = run_overfit(config, views)
    losses = np.array([h["loss"] for h in result.history])
    assert np.isfinite(losses).all()
    assert losses[-8:].mean() < 0.6 * losses[:8].mean(), losses
    assert np.isfinite(result.psnr) and result.psnr > 10


def test_bench_capacity_command_writes_figures_and_a_sheet(tmp_path, capsys):
    import json

    from lirm.engine.cli import main

    assert main(["bench", "capacity", "--steps", "3", "--json", str(tmp_path / "capacity.json")]) == 0
    figures = json.loads((tmp_path / "capacity.json").read_text())
    assert len(figures["history"]) == 3 and len(figures["psnr_per_view"]) == 4 and np.isfinite(figures["psnr"])
    import cv2

    sheet = cv2.imread(str(tmp_path / "capacity.png"))
    assert sheet.shape == (4 * 64, 4 * 64, 3)
    assert "input-view PSNR" in capsys.readouterr().out
