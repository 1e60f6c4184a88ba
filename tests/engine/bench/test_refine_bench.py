"""`lirm bench refine --materials`: the material and relighting columns, and the pictures."""

from __future__ import annotations

import json

import numpy as np
import pytest

from lirm.engine.cli import main
from lirm.engine.evaluation.relight_swaps import SWAPS
from lirm.engine.perceptual.lpips_weights import missing_weights_reason


@pytest.mark.slow
@pytest.mark.parametrize("texture_fit, prefix, title", [
    (["both"], "baked_", "exported with the field's baked textures"),
    (["variant", "--fit-option", "metal_search=False"], "variant_", "with the textures fitted with metal_search=False")])
def test_bench_refine_with_materials_scores_them_and_draws_the_relighting(tmp_path, capsys, texture_fit, prefix, title):
    assert main(["bench", "refine", "--objects", "1", "--size", "48", "--output-views", "1", "--minutes", "0.05",
                 "--init", "hull", "--materials", "--pictures", str(tmp_path / "pictures"), "--json", str(tmp_path / "r.json"),
                 "--texture-fit"] + texture_fit) == 0
    table = capsys.readouterr().out
    assert "| budget | PSNR ↑ | SSIM ↑ | LPIPS ↓ | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ | CD ↓ |" in table
    assert "| budget | relight PSNR-H ↑ | relight PSNR-L ↑ | relight LPIPS ↓ |" in table
    budget = json.loads((tmp_path / "r.json").read_text())["budgets"][0]
    assert all(np.isfinite(budget[k]) for k in ("roughness_psnr", "metallic_psnr", "relight_psnr_h", "relight_psnr_l"))
    # LPIPS of the novel views and of the relit export once its weights are fetched (make setup), else why not.
    if missing_weights_reason("alex"):
        assert "LPIPS skipped: " in table and "lirm fetch lpips" in table
    else:
        assert 0 <= budget["lpips"] < 1.5 and 0 <= budget["relight_lpips"] < 1.5 and "LPIPS skipped" not in table
    # --texture-fit both: the same field's export with its baked textures is scored too, apart; variant:
    # the same field's export fitted with other settings (here without the metal search), both fits timed.
    assert title in table
    assert np.isfinite(budget[prefix + "relight_psnr_l"]) and budget[prefix + "relight_psnr_l"] != budget["relight_psnr_l"]
    assert budget["fit_seconds"] > 0
    if prefix == "variant_":
        assert budget["variant_fit_seconds"] > 0 and "texture fit (s) |" in table
    assert [p.name for p in (tmp_path / "pictures").iterdir()] == ["hull_0.05_min__vase_0.png"]
    # Whether each object's fit heard the material network, and why, is in the JSON and the table.
    row = json.loads((tmp_path / "r.json").read_text())["budgets"][0]["objects"][0]
    assert "the material network" in row["material_network"] and "The material network was heard on" in table


def test_bench_refine_pictures_need_materials(tmp_path, capsys):
    assert main(["bench", "refine", "--objects", "1", "--pictures", str(tmp_path)]) != 0
    assert "add --materials" in capsys.readouterr().err


def test_bench_refine_texture_fit_needs_materials(capsys):
    assert main(["bench", "refine", "--objects", "1", "--texture-fit", "off"]) == 2
    assert "add --materials" in capsys.readouterr().err


def test_bench_refine_variant_needs_its_settings_and_they_must_exist(capsys):
    assert main(["bench", "refine", "--objects", "1", "--materials", "--texture-fit", "variant"]) == 2
    assert "--fit-option KEY=VALUE" in capsys.readouterr().err
    assert main(["bench", "refine", "--objects", "1", "--materials", "--fit-option", "footprint=1"]) == 2
    assert "only with --texture-fit variant" in capsys.readouterr().err
    assert main(["bench", "refine", "--objects", "1", "--materials", "--texture-fit", "variant", "--fit-option", "foot=1"]) != 0
    assert "no texture-fit setting 'foot'" in capsys.readouterr().err
    assert main(["bench", "refine", "--objects", "1", "--materials", "--texture-fit", "variant", "--fit-option", "footprint=0"]) != 0
    assert "footprint must be >= 1" in capsys.readouterr().err


def test_bench_refine_true_lighting_needs_materials(capsys):
    for source in ("truth", "truth-panorama"):
        assert main(["bench", "refine", "--objects", "1", "--lighting", source]) == 2
        assert f"--lighting {source} lights the inverse rendering" in capsys.readouterr().err


def test_bench_refine_swap_study_needs_materials(capsys):
    assert main(["bench", "refine", "--objects", "1", "--swap-study"]) == 2
    assert "add --materials" in capsys.readouterr().err


@pytest.mark.slow
def test_bench_refine_swap_study_takes_the_relighting_apart(tmp_path, capsys):
    assert main(["bench", "refine", "--objects", "1", "--size", "48", "--output-views", "1", "--minutes", "0.05",
                 "--init", "hull", "--materials", "--swap-study", "--json", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert "Where the relighting error comes from" in out and "The export's own materials" in out
    budget = json.loads((tmp_path / "r.json").read_text())["budgets"][0]
    swaps = {k: v for k, v in budget.items() if k.startswith("swap_")}
    assert len(swaps) == 2 * len(SWAPS) and all(np.isfinite(v) for v in swaps.values()), swaps
    # The unswapped torch shading is the relighting test's own render of the export.
    assert abs(budget["swap_export_relight_psnr_l"] - budget["relight_psnr_l"]) < 0.5, budget
    # The export's own materials are scored beside it (a short hull refinement: no better than chance, but measured).
    exported = {k: budget[k] for k in ("exported_albedo_psnr", "exported_roughness_psnr", "exported_metallic_psnr")}
    assert all(np.isfinite(v) and 0.0 < v < 60.0 for v in exported.values()), exported


def test_bench_refine_at_a_fixed_step_count_gives_the_same_fit_twice(tmp_path, capsys):
    """With a wall-clock budget the schedule follows the time (even its first step), so no two runs are
    alike; --steps makes a fit a function of its inputs and settings alone."""
    runs = []
    for k in range(2):
        assert main(["bench", "refine", "--objects", "1", "--size", "48", "--output-views", "1", "--steps", "12",
                     "--init", "hull", "--json", str(tmp_path / f"r{k}.json")]) == 0
        result = json.loads((tmp_path / f"r{k}.json").read_text())
        runs.append(result["budgets"][0])
    out = capsys.readouterr().out
    assert "| 12 steps |" in out
    # Equal steps pair exactly only on one machine: the result says which.
    assert result["machine"]["threads"] >= 1 and result["machine"]["cpu_kernels"], result["machine"]
    assert f"Machine: {result['machine']['device']}" in out
    first, second = runs
    assert first["steps"] == second["steps"] == 12 and first["minutes"] is None
    for key in ("psnr", "ssim", "albedo_psnr", "chamfer"):
        assert first[key] == second[key], key


def test_bench_refine_steps_must_be_positive(capsys):
    assert main(["bench", "refine", "--objects", "1", "--steps", "0"]) == 2
    assert "--steps must be at least 1" in capsys.readouterr().err
