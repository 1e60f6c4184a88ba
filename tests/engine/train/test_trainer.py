"""lirm train on the CPU: the loss falls, a resume continues the exact curve, two gloo processes
train together, and bad input stops before compute is spent."""

from __future__ import annotations

import csv
import json
import os
import socket
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.torch import load_file, save_file

from lirm.engine.errors import LirmUserError
from lirm.engine.model.checkpoint import load_checkpoint, peek_checkpoint
from lirm.engine.synth.training_scenes import TrainingSceneConfig
from lirm.engine.train.trainer import TrainConfig, run_training

# Small scenes rendered once per test session into a shared cache: 16 views (2 sets of up to 6 inputs
# and the targets fit), rendered at the tiny model's 64 px input size.
SCENES = TrainingSceneConfig(views=16, size=64, environment_width=128)


@pytest.fixture(scope="module")
def cache(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("scene_cache")


def _config(out: Path, cache: Path, **kw) -> TrainConfig:
    base = dict(preset="tiny", stage=1, out_dir=str(out), stage_steps=40, scene_pool=1, cache_dir=str(cache),
                scenes=SCENES, checkpoint_every=1000)
    base.update(kw)
    return TrainConfig(**base)


def _csv(path: Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.slow
def test_tiny_training_loss_falls(tmp_path, cache):
    result = run_training(_config(tmp_path / "run", cache, max_steps=40))
    losses = np.array([r["loss"] for r in result.history])
    assert len(losses) == 40 and np.all(np.isfinite(losses))
    assert losses[-10:].mean() < 0.95 * losses[:10].mean(), losses
    rows = _csv(tmp_path / "run" / "metrics.csv")
    assert [int(r["step"]) for r in rows] == list(range(1, 41))
    assert {"loss", "colour", "albedo", "roughness", "metallic", "normal", "perceptual", "loss_update1", "loss_update2"} <= set(rows[0])
    assert float(rows[-1]["lr"]) == pytest.approx(1e-4, rel=0.05)  # the cosine reached the stage's end
    assert float(rows[-1]["inv_beta"]) == pytest.approx(200.0)
    assert any((tmp_path / "run" / "tensorboard").iterdir())
    assert (tmp_path / "run" / "loss_curves.png").is_file()
    # The final checkpoint is an ordinary model checkpoint too.
    model, extra = load_checkpoint(tmp_path / "run" / "last.safetensors")
    assert model.config.name == "tiny" and extra["training"]["step"] == 40


def test_checkpointing_trains_the_same_steps_with_less_memory(tmp_path, cache):
    """`--checkpointing on` recomputes the transformer and the crops' renders in the backward pass: the
    same losses and weights as off (which the H200 slices use for speed), only the memory differs."""
    plain = run_training(_config(tmp_path / "off", cache, max_steps=2, checkpointing="off"))
    recomputed = run_training(_config(tmp_path / "on", cache, max_steps=2, checkpointing="on"))
    np.testing.assert_allclose([r["loss"] for r in recomputed.history], [r["loss"] for r in plain.history], rtol=1e-5)
    assert TrainConfig().uses_checkpointing(torch.device("cpu")) is False  # auto: only on GPUs
    assert TrainConfig().uses_checkpointing(torch.device("cuda")) is True
    with pytest.raises(LirmUserError, match="choose auto, on or off"):
        TrainConfig(checkpointing="sometimes").uses_checkpointing(torch.device("cpu"))


def test_resume_continues_the_exact_loss_curve(tmp_path, cache):
    straight = run_training(_config(tmp_path / "straight", cache, max_steps=6))
    first = run_training(_config(tmp_path / "split", cache, max_steps=3, checkpoint_every=3))
    assert first.checkpoint.name == "stage1_step0000003.safetensors"
    resumed = run_training(_config(tmp_path / "split", cache, max_steps=6, resume=str(first.checkpoint)))
    assert resumed.first_step == 3
    a = [r["loss"] for r in straight.history]
    b = [r["loss"] for r in first.history + resumed.history]
    np.testing.assert_allclose(b, a, rtol=1e-5)
    assert [int(r["step"]) for r in _csv(tmp_path / "split" / "metrics.csv")] == [1, 2, 3, 4, 5, 6]


def test_a_slim_copy_resumes_at_its_step_with_fresh_moments_and_a_warm_up(tmp_path, cache, monkeypatch):
    """The float16 copy carried between GPU slices: a third of the size, continues the same step
    (same data, same schedule) and ramps the learning rate up again because AdamW starts afresh.
    A run whose last step is a checkpoint writes it once, not again on the way out."""
    from lirm.engine.train import trainer
    from lirm.engine.train.trainer import MOMENT_RESTART_STEPS, learning_rate

    written = []
    real_save = trainer.save_slim_checkpoint
    monkeypatch.setattr(trainer, "save_slim_checkpoint", lambda path, model, stage, step, run, optimizer=None: (
        written.append(step), real_save(path, model, stage, step, run)))  # without the optimizer: no second moments
    slim = tmp_path / "slim.safetensors"
    first = run_training(_config(tmp_path / "run", cache, max_steps=2, checkpoint_every=2, slim_copy=str(slim),
                                 batch_scenes=1))
    assert written == [2], written
    assert slim.stat().st_size < 0.4 * first.checkpoint.stat().st_size
    model, extra = load_checkpoint(slim)
    assert extra["training"]["step"] == 2 and extra["training"]["moments"] == "dropped"
    assert {str(t.dtype) for t in load_file(slim).values() if t.is_floating_point()} == {"torch.float16"}
    resumed = run_training(_config(tmp_path / "run", cache, max_steps=4, resume=str(slim), batch_scenes=1))
    assert resumed.first_step == 2 and [r["step"] for r in resumed.history] == [3, 4]
    stage = _config(tmp_path, cache).stage_settings()
    for record, step in zip(resumed.history, (2, 3)):
        expected = learning_rate(stage, step) * (step - 2 + 1) / MOMENT_RESTART_STEPS
        assert record["lr"] == pytest.approx(expected)
    assert [int(r["step"]) for r in _csv(tmp_path / "run" / "metrics.csv")] == [1, 2, 3, 4]


def test_a_slim_copy_with_its_second_moments_resumes_without_a_warm_up(tmp_path, cache, caplog):
    """The trainer writes AdamW's second moments beside the slim copy in 8 bits: a run resumed from it
    restores them (close to the full checkpoint's), starts the first moments afresh and keeps the
    scheduled learning rate; a companion of another step is ignored, and the warm-up comes back."""
    from lirm.engine.train.second_moments import second_moments_path
    from lirm.engine.train.trainer import learning_rate
    from lirm.engine.train.training_checkpoint import load_resume_point

    slim = tmp_path / "slim.safetensors"
    first = run_training(_config(tmp_path / "run", cache, max_steps=2, checkpoint_every=2, slim_copy=str(slim),
                                 batch_scenes=1))
    companion = second_moments_path(slim)
    model = load_checkpoint(slim)[0]
    assert companion.is_file() and companion.stat().st_size < 1.1 * sum(p.numel() for p in model.parameters()) + 2**20
    point = load_resume_point(slim, "tiny")
    assert point.moments_dropped and point.second_moments
    exact = load_resume_point(first.checkpoint, "tiny").optimizer_state
    for name, _ in list(model.named_parameters())[:6]:
        restored, truth = point.optimizer_state[f"{name}/exp_avg_sq"], exact[f"{name}/exp_avg_sq"]
        positive = truth > 0
        ratio = (restored[positive] / truth[positive]).sqrt()
        assert float((ratio - 1).abs().max()) < 0.05, name
        assert not point.optimizer_state[f"{name}/exp_avg"].any()
        assert float(point.optimizer_state[f"{name}/step"]) == float(exact[f"{name}/step"]) == 2.0

    aside = tmp_path / "step2.adam-v.safetensors"
    aside.write_bytes(companion.read_bytes())
    resumed = run_training(_config(tmp_path / "run", cache, max_steps=4, resume=str(slim), batch_scenes=1,
                                   checkpoint_every=2, slim_copy=str(slim)))
    stage = _config(tmp_path, cache).stage_settings()
    assert [r["lr"] for r in resumed.history] == [pytest.approx(learning_rate(stage, s)) for s in (2, 3)]
    assert load_resume_point(slim, "tiny").step == 4 and load_resume_point(slim, "tiny").second_moments

    companion.write_bytes(aside.read_bytes())  # step 2's moments beside step 4's weights
    with caplog.at_level("WARNING"):
        stale = load_resume_point(slim, "tiny")
    assert stale.moments_dropped and not stale.second_moments and "not of the resumed stage 1 step 4" in caplog.text


def test_slim_only_saves_the_slim_copy_alone_and_needs_one(tmp_path, cache):
    """A GPU slice's disk is lost after the call: `--slim-only` writes no full checkpoint (with its moments
    and `last.safetensors`), only the slim copy at the checkpoint cadence, and names it as what to resume."""
    slim = tmp_path / "slim.safetensors"
    result = run_training(_config(tmp_path / "run", cache, max_steps=2, checkpoint_every=1, slim_copy=str(slim),
                                  batch_scenes=1, full_checkpoints=False))
    assert result.checkpoint == slim and peek_checkpoint(slim)[1]["training"]["step"] == 2
    assert not list((tmp_path / "run").glob("*.safetensors"))
    assert [int(r["step"]) for r in _csv(tmp_path / "run" / "metrics.csv")] == [1, 2]
    with pytest.raises(LirmUserError, match="--slim-copy"):
        run_training(_config(tmp_path / "none", cache, max_steps=1, full_checkpoints=False))
    with pytest.raises(LirmUserError, match="must end in .safetensors"):
        run_training(_config(tmp_path / "bad", cache, max_steps=1, slim_copy=str(tmp_path / "slim.pt")))
    assert not (tmp_path / "bad").exists()  # refused before anything was written or computed


def test_batch_scenes_overrides_the_stages_batch():
    config = TrainConfig(preset="small", stage=1, batch_scenes=8)
    assert config.stage_settings().batch_scenes == 8
    assert TrainConfig(preset="small", stage=1).stage_settings().batch_scenes == 32


def test_a_later_stage_starts_from_the_earlier_stages_weights(tmp_path, cache):
    first = run_training(_config(tmp_path / "s1", cache, max_steps=1, checkpoint_every=1))
    # Stage 3 feeds 3 sets of up to 6 inputs: its scenes need 18 views (the trainer refuses fewer).
    second = run_training(_config(tmp_path / "s2", cache, stage=3, max_steps=1, resume=str(first.checkpoint),
                                  scenes=replace(SCENES, views=18)))
    assert second.first_step == 0 and second.last_step == 1
    record = second.history[0]
    assert "numerical_normal" in record and record["loss_update3"] > 0  # stage 3: three updates, SDF normals
    _, extra = peek_checkpoint(tmp_path / "s2" / "last.safetensors")
    assert extra["training"]["stage"] == 3


def test_corrupt_or_wrong_resume_checkpoints_stop_before_training(tmp_path, cache):
    first = run_training(_config(tmp_path / "ok", cache, max_steps=1, checkpoint_every=1))
    truncated = tmp_path / "truncated.safetensors"
    truncated.write_bytes(first.checkpoint.read_bytes()[:5000])
    with pytest.raises(LirmUserError, match="truncated"):
        run_training(_config(tmp_path / "bad", cache, max_steps=2, resume=str(truncated)))
    # Optimizer state removed: it cannot continue the run exactly, and says so.
    tensors = load_file(first.checkpoint)
    header = __import__("safetensors").safe_open(str(first.checkpoint), "pt").metadata()
    stripped = tmp_path / "stripped.safetensors"
    save_file({k: v for k, v in tensors.items() if not k.startswith("training.")}, str(stripped), metadata=header)
    with pytest.raises(LirmUserError, match="no optimizer state"):
        run_training(_config(tmp_path / "bad", cache, max_steps=2, resume=str(stripped)))
    with pytest.raises(LirmUserError, match="'tiny' model but the 'small'"):
        run_training(_config(tmp_path / "bad", cache, preset="small", max_steps=2, resume=str(first.checkpoint)))
    assert not (tmp_path / "bad" / "metrics.csv").exists()


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.slow
def test_two_gloo_processes_train_together(tmp_path, cache):
    out = tmp_path / "ddp"
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc-per-node", "2", "--master-port", str(_free_port()),
           "-m", "lirm.engine.cli", "train", "--preset", "tiny", "--max-steps", "3", "--stage-steps", "40",
           "--scene-pool", "2", "--cache", str(cache), "--out", str(out), "--checkpoint-every", "3", "--device", "cpu"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = _csv(out / "metrics.csv")
    assert [int(r["step"]) for r in rows] == [1, 2, 3]  # one writer: process 0
    _, extra = peek_checkpoint(out / "last.safetensors")
    assert extra["training"]["run"]["world_size"] == 2


def test_cli_train_reports_broken_environment_files_and_goes_on(tmp_path, shared_data, cache):
    envs = tmp_path / "envs"
    envs.mkdir()
    (envs / "good.hdr").write_bytes((shared_data / "envmaps" / "studio_small_03_1k.hdr").read_bytes())
    (envs / "broken.hdr").write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4")
    cmd = [sys.executable, "-m", "lirm.engine.cli", "train", "--max-steps", "1", "--stage-steps", "40", "--scene-pool", "1",
           "--cache", str(cache), "--out", str(tmp_path / "run"), "--environments", str(envs)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "1 usable environments, 1 skipped" in done.stderr and "skipped broken.hdr" in done.stderr
    (envs / "good.hdr").unlink()
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 3 and "no usable HDR environments" in done.stderr


def test_a_second_ctrl_c_stops_at_once_and_still_writes_the_slim_copy(tmp_path, cache):
    import signal
    import time

    out = tmp_path / "run"
    cmd = [sys.executable, "-m", "lirm.engine.cli", "train", "--preset", "tiny", "--stage-steps", "40", "--scene-pool", "1",
           "--cache", str(cache), "--out", str(out), "--checkpoint-every", "1000", "--device", "cpu",
           "--batch-scenes", "8", "--slim-copy", str(tmp_path / "slim.safetensors")]
    # Eight scenes a step keep a step long (seconds) next to the 0.1 s between the two signals: with one
    # scene a step could end between them, and the first request alone would stop the run cleanly.
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 300
        while not (out / "metrics.csv").is_file() or len(_csv(out / "metrics.csv")) < 1:
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()[-3000:] if proc.poll() is not None else "no step"
            time.sleep(0.2)
        # Past the end of step 1's bookkeeping and well inside step 2: a first request landing between
        # step 1's metrics row and its stop check would end the run there, before the second arrives.
        time.sleep(0.5)
        proc.send_signal(signal.SIGINT)
        time.sleep(0.1)
        proc.send_signal(signal.SIGINT)  # the second stops the step where it is
        _, stderr = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130 and "cancelled" in stderr, stderr[-3000:]
    _, extra = peek_checkpoint(tmp_path / "slim.safetensors")
    done = len(_csv(out / "metrics.csv"))
    assert extra["training"]["step"] == done and done < 40


def test_a_ctrl_c_while_the_run_writes_its_slim_copy_does_not_cut_it_short():
    # The race behind a lost slim copy: the first Ctrl-C's step ends just before the second arrives, so
    # the second lands while the run writes what it leaves behind.
    from lirm.engine.train.trainer import StopRequests

    stop = StopRequests()
    stop()
    assert stop.requested
    with pytest.raises(KeyboardInterrupt):
        stop()
    stop.closing = True
    stop()  # logged, not raised


def test_the_trainer_itself_refuses_scenes_too_small_for_the_update_sets(tmp_path, cache):
    from lirm.engine.errors import LirmUsageError

    with pytest.raises(LirmUsageError, match="each scene needs at least 12"):
        run_training(_config(tmp_path / "few", cache, max_steps=1, scenes=replace(SCENES, views=11)))
    assert not (tmp_path / "few").exists()


def test_scene_views_sets_the_views_per_scene_and_must_hold_the_update_sets(tmp_path):
    base = [sys.executable, "-m", "lirm.engine.cli", "train", "--preset", "tiny", "--max-steps", "1", "--stage-steps", "40",
            "--scene-pool", "1", "--cache", str(tmp_path / "cache"), "--device", "cpu"]
    done = subprocess.run(base + ["--out", str(tmp_path / "few"), "--scene-views", "11"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 2 and "each scene needs at least 12" in done.stderr, done.stderr[-2000:]
    assert not (tmp_path / "few").exists()
    done = subprocess.run(base + ["--out", str(tmp_path / "run"), "--scene-views", "12"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    run = json.loads((tmp_path / "run" / "stage1_run.json").read_text())
    assert run["config"]["scenes"]["views"] == 12
    assert len(_csv(tmp_path / "run" / "metrics.csv")) == 1
