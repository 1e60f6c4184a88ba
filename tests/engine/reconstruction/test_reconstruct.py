"""`lirm reconstruct` on a prepared capture (lego renders with known poses and alpha masks: no
COLMAP needed): updates in sets, pictures and states after each, the history in capture.json,
the loud untrained warning, and clear errors for bad checkpoints and folders."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.cli import main
from lirm.engine.model.checkpoint import save_checkpoint
from lirm.engine.model.config import preset
from lirm.engine.model import pretrained
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.state_file import load_state, save_state
from lirm.engine.reconstruction.session import update_sets

FAST = ["--preset", "tiny", "--novel-views", "1", "--render-size", "24", "--grid-resolution", "48"]


def test_update_sets_split_in_frame_order():
    assert update_sets(list("abcdefghij"), 4, None) == [list("abcd"), list("efgh"), list("ij")]
    assert update_sets(list("abcdefghij"), 4, 2) == [list("abcd"), list("efgh")]


def test_update_sets_spread_a_walk_around_over_the_object():
    from lirm.engine.cameras import orbit_cameras

    cameras = {f"f{k:02d}": c for k, c in enumerate(orbit_cameras(24, 20.0, 3.0, 32, 32, 40.0))}  # a 360° walk, 15° apart
    sets = update_sets(sorted(cameras), 4, 3, cameras)
    assert sets[0][0] == "f00" and [len(s) for s in sets] == [4, 4, 4]
    def gaps(frames):
        azimuths = sorted(int(f[1:]) * 15 for f in frames)
        return np.diff(azimuths + [azimuths[0] + 360])

    for chosen in sets[:2]:  # the first updates see the object from all round: no two of their views within 60°
        assert gaps(chosen).min() >= 60, chosen
    used = [f for s in sets for f in s]
    assert len(set(used)) == 12 and gaps(used).max() <= 45  # no view twice; 12 views leave no arc unseen
    assert gaps(sorted(cameras)[:12]).max() == 195  # in frame order the same 12 would be one arc


def test_reconstruct_writes_each_update_and_warns_when_untrained(lego_capture, tmp_path, capsys, monkeypatch):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    monkeypatch.setattr(pretrained, "SHIPPED", {})  # as if no trained weights shipped
    assert main(["reconstruct", str(capture), "--updates", "2"] + FAST) == 0
    out, err = capsys.readouterr()
    assert "UNTRAINED" in err and "UNTRAINED" in out
    for k in (1, 2):
        folder = capture / "reconstruction" / f"update_{k:02d}"
        for channel in ("colour", "albedo", "roughness", "metallic", "normal", "opacity"):
            assert (folder / f"view_00_{channel}.png").exists()
        state = load_state(folder / "state.safetensors")
        assert state.updates == k and state.plane_tokens.shape[1] == preset("tiny").num_plane_tokens
    summary = json.loads((capture / "reconstruction" / "summary.json").read_text())
    assert summary["trained"] is False and len(summary["updates"]) == 2
    updates = Capture.open(capture).updates
    assert [u["update"] for u in updates] == [1, 2]
    assert [len(u["frames"]) for u in updates] == [4, 4] and not set(updates[0]["frames"]) & set(updates[1]["frames"])


def test_reconstruct_with_a_checkpoint_and_bad_ones(lego_capture, tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    torch.manual_seed(1)
    ckpt = save_checkpoint(LIRM(preset("tiny")), tmp_path / "tiny.safetensors", metadata={"trained": True})
    assert main(["reconstruct", str(capture), "--updates", "1", "--checkpoint", str(ckpt)] + FAST) == 0
    out, err = capsys.readouterr()
    assert "UNTRAINED" not in err and "tiny.safetensors" in out
    broken = tmp_path / "broken.safetensors"
    broken.write_bytes(ckpt.read_bytes()[:1000])
    assert main(["reconstruct", str(capture), "--checkpoint", str(broken)] + FAST) == 3
    assert "broken.safetensors" in capsys.readouterr().err
    assert main(["reconstruct", str(tmp_path), "--preset", "tiny"]) == 3
    assert "not a capture folder" in capsys.readouterr().err


def test_state_files_round_trip_and_refuse_garbage(tmp_path):
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).eval()
    state = model.initial_state(1)
    state.plane_tokens.normal_()
    path = save_state(state, tmp_path / "state.safetensors")
    back = load_state(path)
    assert torch.equal(back.plane_tokens, state.plane_tokens) and back.signature == state.signature
    (tmp_path / "junk.safetensors").write_bytes(b"not a state")
    from lirm.engine.errors import LirmUserError

    with pytest.raises(LirmUserError, match="junk.safetensors"):
        load_state(tmp_path / "junk.safetensors")
    assert np.isfinite(back.plane_tokens.numpy()).all()


def test_reconstruct_uses_the_shipped_checkpoint_by_default(lego_capture, tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert pretrained.shipped_checkpoint("tiny") is not None and pretrained.default_preset() == "tiny"
    assert main(["reconstruct", str(capture), "--updates", "1"] + FAST[2:]) == 0
    out, err = capsys.readouterr()
    assert "UNTRAINED" not in err + out and "weights: shipped checkpoint lirm-tiny.safetensors" in out
    assert "about these weights: " in out  # the card's one-line caveat travels with the weights
    summary = json.loads((capture / "reconstruction" / "summary.json").read_text())
    assert summary["trained"] is True and summary["preset"] == "tiny"


def test_export_writes_a_valid_glb_of_the_latest_update(lego_capture, tmp_path, capsys, monkeypatch):
    from lirm.engine.export.gltf_validation import validate_gltf

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    monkeypatch.setattr(pretrained, "SHIPPED", {})  # untrained weights: the warning must reach the user
    assert main(["export", str(capture), "-o", str(tmp_path / "a.glb")]) == 3
    assert "no reconstruction yet" in capsys.readouterr().err
    assert main(["reconstruct", str(capture), "--updates", "1"] + FAST) == 0
    out = tmp_path / "asset.glb"
    assert main(["export", str(capture), "-o", str(out), "--faces", "2000", "--texture", "256", "--grid", "64"]) == 0
    captured = capsys.readouterr()
    assert "UNTRAINED" in captured.err and "faces" in captured.out
    report = validate_gltf(out)
    assert report.errors == 0, report.messages


def test_one_more_update_on_chosen_frames_and_stepping_back(lego_capture, tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    frames = sorted(Capture.open(capture).cameras)
    assert main(["reconstruct", str(capture), "--frames", ",".join(frames[:3])] + FAST) == 0
    assert main(["reconstruct", str(capture), "--frames", frames[5]] + FAST) == 0
    updates = Capture.open(capture).updates
    assert [u["frames"] for u in updates] == [frames[:3], [frames[5]]]
    second = load_state(capture / updates[1]["state"])
    assert second.updates == 2
    # Step back to update 1 and go on with other views: update 2 is set aside, not lost.
    assert main(["reconstruct", str(capture), "--frames", frames[6], "--after", "1"] + FAST) == 0
    updates = Capture.open(capture).updates
    assert [u["frames"] for u in updates] == [frames[:3], [frames[6]]]
    aside = list((capture / "reconstruction" / "set_aside").glob("*/update_02/state.safetensors"))
    assert len(aside) == 1 and torch.equal(load_state(aside[0]).plane_tokens, second.plane_tokens)
    summary = json.loads((capture / "reconstruction" / "summary.json").read_text())
    assert [u["frames"] for u in summary["updates"]] == [frames[:3], [frames[6]]]
    capsys.readouterr()
    assert main(["reconstruct", str(capture), "--frames", "nope"] + FAST) == 3
    assert "no prepared view for nope" in capsys.readouterr().err
    assert main(["reconstruct", str(capture), "--frames", frames[0], "--after", "7"] + FAST) == 3
    assert "cannot continue after update 7" in capsys.readouterr().err


@pytest.mark.parametrize("failure", [KeyboardInterrupt, MemoryError])
def test_an_interrupted_reconstruct_keeps_the_earlier_results(lego_capture, tmp_path, capsys, monkeypatch, failure):
    """Issue 20, case 1: Ctrl-C or running out of memory in the middle of a new `lirm reconstruct`
    leaves the earlier updates listed, in place and usable (export, a next update)."""
    from lirm.engine.reconstruction import session

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "2"] + FAST) == 0
    before = Capture.open(capture).updates
    summary = (capture / "reconstruction" / "summary.json").read_text()
    states = {e["state"]: (capture / e["state"]).read_bytes() for e in before}
    real_apply = session._Session.apply

    def failing_apply(self, state, number, frames, views):
        if number == 2:
            raise failure()
        return real_apply(self, state, number, frames, views)

    monkeypatch.setattr(session._Session, "apply", failing_apply)
    try:
        assert main(["reconstruct", str(capture), "--updates", "3"] + FAST) != 0  # the CLI reports Ctrl-C
    except failure:
        pass
    monkeypatch.setattr(session._Session, "apply", real_apply)
    assert Capture.open(capture).updates == before
    assert {k: (capture / k).read_bytes() for k in states} == states
    assert (capture / "reconstruction" / "summary.json").read_text() == summary
    assert not list((capture / "reconstruction").glob(".building_*"))
    assert not (capture / "reconstruction" / "set_aside").exists()
    capsys.readouterr()
    assert main(["export", str(capture), "-o", str(tmp_path / "a.glb"), "--update", "2", "--faces", "500",
                 "--texture", "64", "--grid", "48"]) == 0
