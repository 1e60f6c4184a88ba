"""LIRM checkpoints: safetensors round trip, fp16 shipping, never pickle, and a clear error for every
bad file a user can hand us."""

from __future__ import annotations

import json
import pickle

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import save_file

from lirm.engine.errors import LirmUserError
from lirm.engine.model.checkpoint import FORMAT, load_checkpoint, peek_checkpoint, save_checkpoint
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM, ViewBatch


@pytest.fixture(scope="module")
def tiny():
    torch.manual_seed(0)
    return LIRM(preset("tiny")).eval()


@pytest.fixture
def saved(tiny, tmp_path):
    return save_checkpoint(tiny, tmp_path / "tiny.safetensors", metadata={"step": 12, "trained": False})


def features(model):
    g = torch.Generator().manual_seed(1)
    views = ViewBatch(torch.rand(1, 2, 3, 64, 64, generator=g), torch.rand(1, 2, 3, 64, 64, generator=g),
                      torch.randn(1, 2, 6, 64, 64, generator=g))
    pts = torch.rand(1, 100, 3, generator=g) * 2 - 1
    with torch.no_grad():
        field = model.decode(model.update(model.initial_state(1), views))
        return field.planes, field.panoramas, field.features(pts)


def test_round_trip_gives_identical_outputs(tiny, saved):
    model, extra = load_checkpoint(saved, expected="tiny")
    assert extra == {"step": 12, "trained": False}
    assert not model.training and model.config == tiny.config
    assert all(t.dtype == torch.float32 for t in model.state_dict().values())
    assert all(torch.equal(a, b) for a, b in zip(features(model), features(tiny)))


def test_file_is_plain_safetensors_with_the_metadata(tiny, saved):
    with safe_open(str(saved), framework="pt") as f:
        meta = f.metadata()
        assert set(f.keys()) == set(tiny.state_dict())
    assert meta["format"] == FORMAT and meta["signature"] == tiny.config.signature()
    assert json.loads(meta["config"]) == tiny.config.to_dict()
    assert json.loads(meta["extra"]) == {"step": 12, "trained": False}
    assert peek_checkpoint(saved) == (tiny.config, {"step": 12, "trained": False})
    assert [p.name for p in saved.parent.iterdir()] == ["tiny.safetensors"]  # no temp file left behind


def test_fp16_is_smaller_and_loads_within_fp16_tolerance(tiny, saved, tmp_path):
    half = save_checkpoint(tiny, tmp_path / "half.safetensors", dtype=torch.float16)
    assert half.stat().st_size < 0.6 * saved.stat().st_size
    with safe_open(str(half), framework="pt") as f:
        assert all(f.get_tensor(k).dtype == torch.float16 for k in f.keys())
    model, _ = load_checkpoint(half)
    assert all(t.dtype == torch.float32 for t in model.state_dict().values())
    torch.testing.assert_close(features(model), features(tiny), atol=2e-2, rtol=2e-2)


def test_loading_never_unpickles(saved, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("pickle used")

    for mod, name in ((pickle, "load"), (pickle, "loads"), (pickle, "Unpickler"), (torch, "load")):
        monkeypatch.setattr(mod, name, refuse)
    load_checkpoint(saved)
    peek_checkpoint(saved)


def expect_error(path, match, **kwargs):
    with pytest.raises(LirmUserError, match=match) as err:
        load_checkpoint(path, **kwargs)
    assert path.name in str(err.value) and "\n" not in str(err.value)
    return str(err.value)


def test_pickle_files_are_refused_unread(tiny, tmp_path):
    path = tmp_path / "model.pt"
    torch.save(tiny.state_dict(), path)
    expect_error(path, r"only \.safetensors checkpoints are accepted")


def test_missing_file(tmp_path):
    expect_error(tmp_path / "nowhere.safetensors", "does not exist")


@pytest.mark.parametrize("cut", [0.5, 0.99, 20, 4])
def test_truncated_file(saved, cut):
    data = saved.read_bytes()
    saved.write_bytes(data[: int(len(data) * cut) if cut < 1 else cut])
    expect_error(saved, "not a valid .safetensors file or is truncated")
    with pytest.raises(LirmUserError, match="truncated"):
        peek_checkpoint(saved)


@pytest.mark.parametrize("data", [b"", b"garbage " * 100, bytes(range(256)) * 8,
                                  (12).to_bytes(8, "little") + b"{not json!!}"])
def test_garbage_file(tmp_path, data):
    path = tmp_path / "junk.safetensors"
    path.write_bytes(data)
    expect_error(path, "not a valid .safetensors file")


def test_safetensors_file_that_is_not_a_lirm_checkpoint(tmp_path):
    path = tmp_path / "other.safetensors"
    save_file({"w": torch.zeros(2)}, str(path))
    expect_error(path, "not a LIRM checkpoint")
    save_file({"w": torch.zeros(2)}, str(path), metadata={"format": "lirm-checkpoint/99"})
    expect_error(path, "lirm-checkpoint/99")


def rewrite(path, tensors=None, **meta):
    """Re-save a checkpoint with some tensors and header fields replaced."""
    with safe_open(str(path), framework="pt") as f:
        old = {k: f.get_tensor(k) for k in f.keys()}
        header = {**f.metadata(), **meta}
    save_file(tensors(old) if tensors else old, str(path), metadata=header)


@pytest.mark.parametrize("config", ["{broken", "[1, 2]", json.dumps({"name": "x", "colour": "rainbow"}),
                                    json.dumps({"name": "x", "no_such_field": 1})])
def test_config_that_does_not_parse(saved, config):
    rewrite(saved, config=config)
    expect_error(saved, "unreadable model config")


def test_other_preset_than_expected(saved, tiny):
    msg = expect_error(saved, "holds the 'tiny' model but the 'small' model was asked for", expected="small")
    assert "--preset tiny" in msg
    expect_error(saved, "'small' model was asked for", expected=preset("small"))
    # Same name, other architecture: say so rather than suggest the same preset.
    expect_error(saved, "architecture differs", expected=preset("tiny", depth=3))
    expect_error(saved, "unknown model preset", expected="huge")
    assert load_checkpoint(saved, expected=tiny.config)[0].config == tiny.config


def test_missing_unexpected_and_misshaped_tensors(saved):
    def damage(t):
        names = sorted(t)
        del t[names[0]]
        t["stray.weight"] = torch.zeros(3)
        t[names[1]] = torch.zeros(7, 7)
        return t

    rewrite(saved, damage)
    msg = expect_error(saved, "does not fit its model config")
    assert "1 missing" in msg and "stray.weight" in msg and "(7, 7)" in msg


def test_nan_or_inf_weights(saved):
    name = "plane_pos"

    def poison(t):
        t[name][0, 0, 0] = float("nan")
        return t

    rewrite(saved, poison)
    expect_error(saved, f"NaN or infinite weights in {name}")


def test_save_refuses_non_finite_weights_and_other_suffixes(tmp_path):
    model = LIRM(preset("tiny"))
    with pytest.raises(LirmUserError, match=r"\.safetensors"):
        save_checkpoint(model, tmp_path / "model.pt")
    with torch.no_grad():
        model.plane_pos[0, 0, 0] = 1e6  # overflows fp16
    with pytest.raises(LirmUserError, match="float32"):
        save_checkpoint(model, tmp_path / "m.safetensors", dtype=torch.float16)
    assert not list(tmp_path.iterdir())
