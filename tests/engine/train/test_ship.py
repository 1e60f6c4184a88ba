"""lirm ship: a training checkpoint becomes fp16 weights without optimizer state, plus a model card
whose facts come from the run's files; the shipped weights load through the default path."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import torch
from safetensors import safe_open

from lirm.engine.errors import LirmUserError
from lirm.engine.model.checkpoint import TRAINING_PREFIX, load_checkpoint
from lirm.engine.model.pretrained import load_model
from lirm.engine.synth.training_scenes import TrainingSceneConfig
from lirm.engine.train.ship import read_stage_record, ship
from lirm.engine.train.trainer import TrainConfig, run_training


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("ship")
    config = TrainConfig(preset="tiny", stage=1, out_dir=str(root / "run"), stage_steps=40, max_steps=4, scene_pool=1,
                         cache_dir=str(root / "cache"), scenes=TrainingSceneConfig(views=16, size=64, environment_width=128),
                         checkpoint_every=2)
    run_training(config)
    return root / "run"


def test_ship_writes_fp16_weights_and_a_card_from_the_run(run_dir, tmp_path):
    out = tmp_path / "resources" / "lirm-tiny.safetensors"
    table = tmp_path / "eval.md"
    table.write_text("### a table\n\n| after update | PSNR |\n|---|---|\n| 1 | 17.00 |\n")
    notes = tmp_path / "notes.md"
    notes.write_text("## Limitations\n\nIt is tiny.\n")
    weights, card = ship(run_dir / "stage1_step0000002.safetensors", out, [run_dir], [table], notes, note="a caveat")
    with safe_open(str(weights), "pt") as f:
        names = list(f.keys())
        assert not any(n.startswith(TRAINING_PREFIX) for n in names)  # no AdamW moments
        assert {f.get_tensor(n).dtype for n in names if f.get_tensor(n).is_floating_point()} == {torch.float16}
        meta = json.loads(f.metadata()["extra"])
    assert meta["trained"] is True and meta["note"] == "a caveat" and meta["training"] == {"stage": 1, "step": 2}
    # The card counts the run up to the shipped step, not the steps after it.
    assert meta["stages"][0]["steps"] == 2 and meta["stages"][0]["of"] == 40
    text = card.read_text()
    for fact in ("preset `tiny`", "float16", "sha256", "generator version 1", "data seed 0", "| 1 | 2 / 40 | 2 |",
                 "on CPU", "### a table", "It is tiny.", "a caveat"):
        assert fact in text, fact
    # fp16 weights give the same field as the fp32 checkpoint, to fp16 precision.
    shipped, _ = load_checkpoint(weights)
    original, _ = load_checkpoint(run_dir / "stage1_step0000002.safetensors")
    for (name, a), b in zip(original.state_dict().items(), shipped.state_dict().values()):
        torch.testing.assert_close(b, a, atol=2e-3, rtol=2e-3, msg=name)
    source = load_model(weights)
    assert source.trained and source.note == "a caveat"


def test_ship_refuses_what_it_cannot_describe(run_dir, tmp_path):
    with pytest.raises(LirmUserError, match="one stageN_run.json"):
        read_stage_record(tmp_path)
    with pytest.raises(LirmUserError, match="no such file"):
        ship(tmp_path / "none.safetensors", tmp_path / "w.safetensors", [run_dir], [], None)
    with pytest.raises(LirmUserError, match="--runs"):
        ship(run_dir / "last.safetensors", tmp_path / "w.safetensors", [], [], None)


def test_lirm_ship_command(run_dir, tmp_path):
    out = tmp_path / "w" / "lirm-tiny.safetensors"
    done = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "ship", str(run_dir / "last.safetensors"),
                           "--runs", str(run_dir), "-o", str(out)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (out.parent / "MODEL_CARD.md").is_file() and "MB" in done.stdout
