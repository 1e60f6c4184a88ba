"""`lirm bench model` (engine/bench/model_bench.py): the result's shape and its counts, never its timings."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from lirm.engine.bench.model_bench import (
    ModelBenchConfig,
    baseline_sizes,
    count_update_flops,
    gpu_peak_flops,
    run_model_bench,
)
from lirm.engine.bench.peak_memory import PeakMemory, release_memory
from lirm.engine.errors import LirmUserError
from lirm.engine.model.config import preset

VIEWS = 2


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    path = tmp_path_factory.mktemp("model_bench") / "out" / "bench.json"
    messages: list[str] = []
    config = ModelBenchConfig(preset="tiny", updates=2, views_per_update=VIEWS, baseline_updates=(1, 2, 3),
                              baseline_max_views=2 * VIEWS, peak_flops=1e12, json_path=path)
    result = run_model_bench(config, progress=messages.append)
    return result, json.loads(path.read_text()), messages


def test_json_has_the_required_keys_and_types(bench):
    result, data, messages = bench
    assert data == json.loads(json.dumps(result.to_dict()))
    assert data["preset"] == "tiny" and data["device"] == "cpu" and data["views_per_update"] == VIEWS
    assert data["memory_method"] in ("vmhwm", "ru_maxrss")
    assert isinstance(data["flops_per_update"], int)
    assert isinstance(data["decode_seconds"], float) and data["decode_seconds"] >= 0
    assert set(data["tokens"]) == {"plane", "nde", "image", "total"}
    assert [u["update"] for u in data["updates"]] == [1, 2]
    for row in data["updates"]:
        assert isinstance(row["seconds"], float) and row["seconds"] > 0
        assert isinstance(row["peak_memory_bytes"], int)
    for row in data["baseline"]:
        assert {"views", "seconds", "peak_memory_bytes", "tokens", "flops"} <= set(row)
    summary = data["summary"]
    assert isinstance(summary["median_seconds"], float)
    assert isinstance(summary["peak_memory_growth"], float)
    assert summary["peak_flops"] == 1e12
    assert summary["peak_flops_fraction"] == pytest.approx(summary["achieved_flops_per_second"] / 1e12)
    assert messages, "the progress callback was never called"
    text = result.table()
    assert "baseline" in text and "tokens per update" in text


def test_tokens_follow_the_config_and_do_not_grow_with_updates(bench):
    _, data, _ = bench
    cfg = preset("tiny")
    image = VIEWS * cfg.image_tokens_per_view(cfg.image_size, cfg.image_size)
    expected = {"plane": cfg.num_plane_tokens, "nde": cfg.num_nde_tokens, "image": image,
                "total": cfg.num_plane_tokens + cfg.num_nde_tokens + image}
    assert data["tokens"] == expected
    assert all(row["tokens"] == expected for row in data["updates"])
    assert len({row["state_storage_bytes"] for row in data["updates"]}) == 1


def test_baseline_tokens_and_flops_grow_with_the_views(bench):
    _, data, _ = bench
    cfg = preset("tiny")
    per_view = cfg.image_tokens_per_view(cfg.image_size, cfg.image_size)
    rows = data["baseline"]
    assert [r["views"] for r in rows] == [VIEWS, 2 * VIEWS]
    assert [r["tokens"]["image"] for r in rows] == [VIEWS * per_view, 2 * VIEWS * per_view]
    assert all(r["tokens"]["plane"] == cfg.num_plane_tokens for r in rows)
    assert rows[0]["flops"] < rows[1]["flops"]
    # baseline_max_views = 2 * VIEWS leaves out the 3-update size, and says why
    assert [s["views"] for s in data["baseline_skipped"]] == [3 * VIEWS]
    assert "baseline_max_views" in data["baseline_skipped"][0]["reason"]


def test_flops_are_positive_and_the_meta_count_matches_the_real_one(bench):
    _, data, _ = bench
    assert data["flops_per_update"] > 0
    # the baseline's 1-update size is counted on meta tensors; the progressive update on real ones
    assert data["baseline"][0]["flops"] == data["flops_per_update"]
    cfg = preset("tiny")
    assert 0 < count_update_flops(cfg, 1) < count_update_flops(cfg, 2) < count_update_flops(cfg, 4)


def test_peak_memory_is_measured(bench):
    _, data, _ = bench
    for row in data["updates"] + data["baseline"]:
        assert row["peak_memory_bytes"] > 0
        assert row["peak_memory_bytes"] >= row["peak_increase_bytes"] >= 0


def test_peak_memory_meter_sees_an_allocation_and_resets():
    meter = PeakMemory("cpu")
    if not meter.resettable:
        pytest.skip("/proc/self/clear_refs is not writable here: ru_maxrss cannot be reset")
    release_memory("cpu")
    meter.reset()
    before = meter.current()
    block = np.ones(64 * 2**20 // 8)  # 64 MiB, touched
    assert meter.peak() >= before + 60 * 2**20
    del block
    release_memory("cpu")
    meter.reset()
    assert meter.peak() < before + 32 * 2**20


def test_baseline_sizes_and_gpu_peaks():
    assert baseline_sizes(8) == (1, 2, 4, 8)
    assert baseline_sizes(6) == (1, 2, 4, 6)
    assert baseline_sizes(1) == (1,)
    assert gpu_peak_flops("NVIDIA H100 80GB HBM3") == 989e12
    assert gpu_peak_flops("NVIDIA H200") == 989e12
    assert gpu_peak_flops("NVIDIA A100-SXM4-80GB") == 312e12
    assert gpu_peak_flops("NVIDIA H100 PCIe") < 989e12
    assert gpu_peak_flops("Tesla T4") is None


def test_bad_requests_are_user_errors():
    with pytest.raises(LirmUserError):
        run_model_bench(ModelBenchConfig(preset="huge"))
    with pytest.raises(LirmUserError):
        run_model_bench(ModelBenchConfig(preset="tiny", updates=0))
    if not torch.cuda.is_available():
        with pytest.raises(LirmUserError, match="cuda"):
            run_model_bench(ModelBenchConfig(preset="tiny", device="cuda"))


def test_an_image_size_override_changes_the_image_tokens():
    cfg = preset("tiny")
    result = run_model_bench(ModelBenchConfig(preset="tiny", updates=1, views_per_update=1, baseline=False, image_size=128))
    assert result.image_size == 128
    assert result.tokens["image"] == cfg.image_tokens_per_view(128, 128) == 4 * cfg.image_tokens_per_view(64, 64)
    with pytest.raises(LirmUserError, match="patch"):
        run_model_bench(ModelBenchConfig(preset="tiny", updates=1, baseline=False, image_size=100))


def test_memory_does_not_grow_over_eight_updates():
    """The issue's check: peak memory after 8 updates within 5% of after 1, and the state holds
    exactly its tokens (no slice keeping the transformer's whole output alive)."""
    result = run_model_bench(ModelBenchConfig(preset="tiny", updates=8, baseline=False))
    peaks = [u["peak_memory_bytes"] for u in result.updates]
    assert len(peaks) == 8 and abs(peaks[-1] / peaks[0] - 1.0) < 0.05, peaks
    assert all(u["state_storage_bytes"] == u["state_bytes"] for u in result.updates)
    assert len({u["state_bytes"] for u in result.updates}) == 1


def test_bench_model_command(tmp_path, capsys):
    from lirm.engine.cli import main

    assert main(["bench", "model", "--preset", "tiny", "--updates", "2", "--no-baseline", "--json", str(tmp_path / "m.json")]) == 0
    figures = json.loads((tmp_path / "m.json").read_text())
    assert figures["preset"] == "tiny" and len(figures["updates"]) == 2
    assert all(u["seconds"] > 0 and u["peak_memory_bytes"] > 0 for u in figures["updates"])
