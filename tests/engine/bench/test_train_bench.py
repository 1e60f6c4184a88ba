"""`lirm bench train` on the CPU: both checkpointing settings timed on the trainer's own step, a
profiled step with its parts and operators, and the figures as JSON."""

from __future__ import annotations

import json

import pytest

from lirm.engine.bench.train_step_bench import TrainBenchConfig, run_train_bench
from lirm.engine.errors import LirmUsageError
from lirm.engine.train.perceptual import lpips_available


def test_train_bench_times_both_settings_and_profiles_a_step(tmp_path):
    out = tmp_path / "train.json"
    result = run_train_bench(TrainBenchConfig(preset="tiny", batch_scenes=2, steps=1, checkpointing="both", profile=True,
                                              profile_rows=5, json_path=out))
    assert [run.checkpointing for run in result.runs] == [True, False]
    assert all(len(run.step_seconds) == 1 and run.step_seconds[0] > 0 for run in result.runs)
    assert result.rays_per_step == 2 * 2 * 4 * 16 * 16  # scenes x update sets x targets x 16^2 crops (tiny, stage 1)
    assert {"update", "decode", "render_and_losses", "backward", "optimizer"} <= set(result.phases)
    assert result.phases["render_and_losses"] > 0 and len(result.top_operators) == 5
    figures = json.loads(out.read_text())
    assert figures["runs"][0]["median_seconds"] == result.runs[0].median_seconds
    assert "gradient checkpointing off" in result.table()
    # The perceptual loss training would take here: LPIPS where its weights were fetched, else the substitute.
    lpips_here, _ = lpips_available()
    assert result.perceptual == ("lpips-vgg" if lpips_here else "ms-ssim+gradient") == figures["perceptual"]
    assert f"perceptual loss: {result.perceptual}" in result.table()


def test_train_bench_refuses_too_few_scene_views():
    with pytest.raises(LirmUsageError, match="at least 12"):
        run_train_bench(TrainBenchConfig(preset="tiny", batch_scenes=2, scene_views=8))
