"""lirm eval: the paper's table after updates 1-4, on the synthetic held-out set and on a capture."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest
import torch

from lirm.engine.evaluation.evaluate import EvalConfig, evaluate_heldout
from lirm.engine.evaluation.heldout_sets import synthetic_heldout
from lirm.engine.model.checkpoint import save_checkpoint
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.volume_renderer import VolumeRenderConfig
from lirm.engine.perceptual.lpips_weights import missing_weights_reason


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("ckpt") / "tiny.safetensors"
    save_checkpoint(LIRM(preset("tiny")), path)
    return path


def test_heldout_set_is_fixed_and_disjoint_from_inputs(renderer):
    a = synthetic_heldout(renderer, 2, 32, surface_points=100)
    b = synthetic_heldout(renderer, 2, 32, surface_points=100)
    assert [o.name for o in a] == ["vase#0", "mug#1"]
    assert (a[0].views.image == b[0].views.image).all()
    for obj in a:
        assert len(obj.views.cameras) == 48 and len(obj.protocol.input_sets) == 4
        used = {i for s in obj.protocol.input_sets for i in s}
        assert not used & set(obj.protocol.outputs) and len(obj.protocol.outputs) == 12
        assert obj.surface.shape == (100, 3) and abs(obj.surface).max() <= 0.8 + 1e-4


def test_later_objects_alone_are_the_same_objects(renderer):
    whole = synthetic_heldout(renderer, 3, 32, surface_points=100)
    alone = synthetic_heldout(renderer, 1, 32, surface_points=100, first=2)
    assert [o.name for o in alone] == ["toy_block#2"]
    assert alone[0].lit_by == whole[2].lit_by
    assert (alone[0].views.image == whole[2].views.image).all()
    assert alone[0].relight.rotation_deg == whole[2].relight.rotation_deg
    for view, radiance in whole[2].relight.radiance.items():
        assert (alone[0].relight.radiance[view] == radiance).all()
    with pytest.raises(ValueError, match="at least 0"):
        synthetic_heldout(renderer, 1, 32, first=-1)


def test_eval_scores_every_update(renderer):
    objects = synthetic_heldout(renderer, 1, 32, surface_points=500)
    config = EvalConfig(render=VolumeRenderConfig(samples_per_ray=32, numerical_normals=False), mesh_resolution=24,
                        chamfer_points=500, output_views=2)
    model = LIRM(preset("tiny"))
    result = evaluate_heldout(model, objects, config)
    assert [r.update for r in result.rows] == [1, 2, 3, 4]
    for row in result.rows:
        assert 0 < row.psnr < 60 and -1 <= row.ssim <= 1 and row.views == 2
        assert row.albedo_psnr is not None and row.roughness_psnr is not None and row.chamfer is not None


@pytest.mark.slow
def test_lirm_eval_writes_the_markdown_table(tmp_path, tiny_checkpoint):
    out = tmp_path / "table.md"
    cmd = [sys.executable, "-m", "lirm.engine.cli", "eval", str(tiny_checkpoint), "--objects", "1", "--size", "32",
           "--output-views", "2", "--mesh-resolution", "24", "--updates", "2", "--baselines", "--refine", "--refine-minutes", "0.05",
           "-o", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    table = out.read_text()
    assert table in done.stdout
    assert "| reconstructor | after update | PSNR ↑ | SSIM ↑ | LPIPS ↓ | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ | CD ↓ |" in table
    for name in ("tiny.safetensors", "untrained 'tiny' (seed 0)", "mean-colour sphere", "carved visual hull"):
        for update in (1, 2):
            assert f"| {name} | {update} | " in table
    # The refined rows: after the last update, on the same views, with the seconds each took.
    assert "| refined from LIRM | 2 | " in table and "| refined from the hull | 2 | " in table
    numbers = json.loads(out.with_suffix(".json").read_text())
    assert [r["update"] for r in numbers["rows"]] == [1, 2]
    assert set(numbers["baselines"]) == {"untrained 'tiny' (seed 0)", "mean-colour sphere", "carved visual hull",
                                         "refined from LIRM", "refined from the hull"}
    refined = numbers["baselines"]["refined from LIRM"]["rows"][0]
    assert refined["seconds"] > 2 and refined["psnr"] > 5 and numbers["rows"][1]["seconds"] > 0
    # LPIPS for every row, the refined ones too, once its weights are fetched (`make setup` does it).
    rows = numbers["rows"] + [r for b in numbers["baselines"].values() for r in b["rows"]]
    if missing_weights_reason("alex"):
        assert numbers["lpips"].startswith("LPIPS skipped") and all(r["lpips"] is None for r in rows)
    else:
        assert numbers["lpips"] == "computed" and all(0.0 <= r["lpips"] < 1.5 for r in rows)


def test_lirm_eval_refuses_a_bad_set_and_a_missing_checkpoint(tmp_path, tiny_checkpoint):
    done = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "eval", str(tiny_checkpoint), "--set", str(tmp_path)],
                          capture_output=True, text=True)
    assert done.returncode == 3 and "not 'synthetic', 'gltf' or a capture folder" in done.stderr
    done = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "eval", str(tmp_path / "none.safetensors")],
                          capture_output=True, text=True)
    assert done.returncode == 3 and "does not exist" in done.stderr
    done = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "eval", "--no-relight", "--pictures", str(tmp_path / "p")],
                          capture_output=True, text=True)
    assert done.returncode != 0 and "--pictures shows the relighting test" in done.stderr


def test_gltf_heldout_set_renders_the_models_under_the_hdris(renderer, shared_data):
    from lirm.engine.evaluation.heldout_sets import gltf_heldout

    models = [shared_data / "pbr_models" / "Avocado_tex256.glb", shared_data / "pbr_models" / "WaterBottle_tex256.glb"]
    envs = [shared_data / "envmaps" / "studio_small_03_1k.hdr"]
    objects = gltf_heldout(renderer, models, envs, size=24, surface_points=200)
    assert [o.name for o in objects] == ["Avocado_tex256", "WaterBottle_tex256"]
    for obj in objects:
        assert obj.views.mask.mean() > 0.05 and obj.views.albedo.max() > 0
        assert abs(obj.surface).max() <= 0.8 + 1e-4


def test_eval_on_a_real_capture_holds_out_every_fourth_view(lego_capture):
    from lirm.engine.evaluation.heldout_sets import capture_heldout

    (obj,) = capture_heldout(lego_capture)
    assert obj.protocol.outputs == [3, 7] and obj.protocol.input_sets == [[0, 1, 2, 4], [5, 6]]
    assert obj.surface is None and obj.views.albedo is None
    config = EvalConfig(render=VolumeRenderConfig(samples_per_ray=24, numerical_normals=False), mesh_resolution=16)
    result = evaluate_heldout(LIRM(preset("tiny")), [obj], config, set_name="capture")
    assert [r.update for r in result.rows] == [1, 2]
    assert all(r.albedo_psnr is None and r.chamfer is None and r.views == 2 for r in result.rows)


def test_refined_rows_on_a_real_capture_fit_the_inputs_and_score_the_held_out_views(lego_capture):
    from lirm.engine.evaluation.heldout_sets import capture_heldout
    from lirm.engine.evaluation.refined_rows import evaluate_refined
    from lirm.engine.refine.config import RefineConfig

    (obj,) = capture_heldout(lego_capture)
    config = EvalConfig(updates=2, render=VolumeRenderConfig(samples_per_ray=24, numerical_normals=False), mesh_resolution=16)
    refine = RefineConfig(minutes=None, iterations=8, rays_per_step=256, plane_resolutions=(32,), hull_init_steps=5)
    torch.manual_seed(0)
    result = evaluate_refined(LIRM(preset("tiny")).eval(), [obj], config, refine, "hull", set_name="capture")
    (row,) = result.rows
    assert row.update == 2 and row.views == 2 and row.seconds > 0 and 5 < row.psnr < 60
