"""Issue 20: SIGKILL `lirm capture`, `lirm reconstruct`, `lirm refine` and `lirm export` at random
moments on a small capture. After each kill the capture opens, every earlier result is still there
and usable, and a re-run (or `--resume`) completes."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.model.field_state import load_field

pytestmark = pytest.mark.slow

LIRM = [sys.executable, "-m", "lirm.engine.cli"]
FAST = ["--preset", "tiny", "--novel-views", "1", "--render-size", "24", "--grid-resolution", "48"]
MOMENTS = random.Random(20).sample([1.5, 3.0, 4.5, 6.0, 8.0, 11.0], 2)  # seconds after the start


def _lirm(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(LIRM + list(args), capture_output=True, text=True, timeout=timeout)


def _kill_after(seconds: float, *args: str) -> bool:
    """Start `lirm ARGS`, SIGKILL it after `seconds`; True if it was still running then."""
    process = subprocess.Popen(LIRM + list(args), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                               start_new_session=True)
    try:
        process.wait(timeout=seconds)
        return False
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
        return True


def _history_is_usable(capture: Path, earlier: list[dict]) -> list[dict]:
    """The capture opens; each step it lists has its state; the earlier steps are all still there."""
    opened = Capture.open(capture)
    for entry in opened.updates:
        assert (capture / entry["state"]).is_file(), entry
    listed = {e["state"]: e for e in opened.updates}
    for entry in earlier:
        assert (capture / entry["state"]).is_file(), f"an earlier result is gone: {entry['state']}"
    if opened.updates:
        from lirm.engine.model.pretrained import load_model

        model = load_model(None, "tiny").model
        load_field(capture / opened.updates[-1]["state"], model)  # the newest step loads
    return list(listed.values())


def test_lirm_module_runs_as_a_command():
    assert _lirm("--help").returncode == 0


@pytest.mark.parametrize("moment", MOMENTS)
def test_killing_reconstruct_and_refine_keeps_the_history(lego_capture, tmp_path, moment):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert _lirm("reconstruct", str(capture), "--updates", "2", *FAST).returncode == 0
    _kill_after(moment, "reconstruct", str(capture), "--updates", "2", *FAST)
    after = _history_is_usable(capture, [])
    assert len(after) == 2  # the old two or the new two, never a mixture or nothing
    refine = ["refine", str(capture), "--iterations", "15", "--minutes", "1", "--init", "hull", "--novel-views", "1",
              "--render-size", "24", "--grid-resolution", "48"]
    before_refine = Capture.open(capture).updates
    _kill_after(moment, *refine)
    after = _history_is_usable(capture, before_refine)
    assert len(after) in (2, 3) and after[:2] == before_refine
    result = _lirm(*refine)
    assert result.returncode == 0, result.stderr
    final = _history_is_usable(capture, before_refine)
    assert final[-1].get("kind") == "refine"
    assert not list((capture / "reconstruction").glob(".building_*"))


@pytest.mark.parametrize("moment", MOMENTS)
def test_killing_capture_leaves_a_folder_that_resumes(tmp_path, shared_data, moment):
    lego = shared_data / "synth_nerf_lego_train"
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(0, 40, 5):
        shutil.copy(lego / "train" / f"r_{i}.png", photos / f"r_{i}.png")
    out = tmp_path / "capture"
    options = ["--masks", "alpha", "--size", "32", "--poses", str(lego / "transforms_train.json")]
    _kill_after(moment, "capture", str(photos), "-o", str(out), *options)
    if (out / "capture.json").exists():
        Capture.open(out)
        result = _lirm("capture", "--resume", str(out), *options)
    else:
        result = _lirm("capture", str(photos), "-o", str(out), *options)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "network views prepared: 8" in result.stdout


@pytest.mark.parametrize("moment", MOMENTS[:1])
def test_killing_export_leaves_no_half_file(lego_capture, tmp_path, moment):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert _lirm("reconstruct", str(capture), "--updates", "1", *FAST).returncode == 0
    asset = tmp_path / "asset.glb"
    export = ["export", str(capture), "-o", str(asset), "--faces", "800", "--texture", "64", "--grid", "48"]
    _kill_after(moment, *export)
    if asset.exists():  # only ever the whole file
        from lirm.engine.export.gltf_validation import validate_gltf

        assert validate_gltf(asset).errors == 0
    result = _lirm(*export)
    assert result.returncode == 0, result.stderr
    assert asset.is_file()
    _history_is_usable(capture, Capture.open(capture).updates)
