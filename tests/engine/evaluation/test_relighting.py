"""The relighting test: an export rendered under a new environment against the truth under it."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from lirm.engine.cameras import Camera, look_at
from lirm.engine.evaluation.relighting import RelightConfig, Relighter, relight_metrics, render_relight_truth
from lirm.engine.model.analytic_fields import MaterialPattern, SphereField
from lirm.renderer.material import PBRMaterial
from lirm.renderer.primitives import uv_sphere
from lirm.renderer.procedural_environments import make_procedural_environment

ORANGE = (0.7, 0.35, 0.1)


class _Plain(MaterialPattern):
    """One dielectric material everywhere (the analytic fields' pattern is a checker and a metal half)."""

    def metallic(self, p: torch.Tensor) -> torch.Tensor:
        return torch.zeros(p.shape[:-1], dtype=p.dtype, device=p.device)


def test_the_metrics_ignore_a_global_scale_and_see_errors():
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.05, 2.0, (32, 32, 3))
    mask = np.zeros((32, 32))
    mask[8:24, 8:24] = 1.0
    same = relight_metrics(truth * 3.0, mask, truth, mask, 0.0)  # albedo x light: only known up to scale
    assert same["relight_psnr_h"] > 200 and same["relight_psnr_l"] > 200
    noisy = relight_metrics(truth * rng.uniform(0.8, 1.2, truth.shape), mask, truth, mask, 0.0)
    assert 10.0 < noisy["relight_psnr_l"] < 60.0 and noisy["relight_ssim"] < 1.0
    missing = np.zeros_like(mask)
    missing[8:16, 8:24] = 1.0  # half the object not there: the true mask's pixels score it
    half = truth * missing[..., None]  # a render is black where it has no surface
    assert relight_metrics(half, missing, truth, mask, 0.0)["relight_psnr_l"] < noisy["relight_psnr_l"]
    # The silhouette's edge pixel is not scored (Stanford-ORB's margin), its inside is.
    edge = truth.copy()
    edge[8, 8:24] = 0.0
    assert relight_metrics(edge, mask, truth, mask, 0.0)["relight_psnr_l"] > 200
    inner = truth.copy()
    inner[12, 8:24] = 0.0
    assert relight_metrics(inner, mask, truth, mask, 0.0)["relight_psnr_l"] < 60



def test_a_view_that_sees_nothing_to_score_adds_nothing_to_any_column(renderer):
    """A flat panel seen edge-on has no pixel left once the mask is shrunk by the margin: that view
    is skipped by the relighting columns and by the swap study alike (the study once failed there)."""
    environment = make_procedural_environment("studio", width=128)
    cameras = [Camera.from_fov(48, 48, 40.0, look_at((3.0, 0.0, 1.0), (0, 0, 0))),
               Camera.from_fov(48, 48, 40.0, look_at((3.0, 0.0, 1.0), (6.0, 0.0, 1.0)))]  # looks away
    material = PBRMaterial(base_color_factor=(*ORANGE, 1.0), roughness_factor=0.5, metallic_factor=0.0)
    truth = render_relight_truth(renderer, [uv_sphere(0.5, segments=48, material=material)], np.eye(4), cameras, [0, 1],
                                 environment, 0.0, 0.0, keep_gbuffers=True)
    assert not truth.mask[1].any()
    obj = SimpleNamespace(name="sphere", relight=truth, views=SimpleNamespace(cameras=cameras))
    relighter = Relighter(RelightConfig(grid=48, faces=3000, texture=64, swap_study=True))
    scores = {}
    try:
        relighter.score(SphereField(0.5, pattern=_Plain(colour_a=ORANGE, colour_b=ORANGE)), obj, [0, 1], scores)
    finally:
        relighter.release()
    assert len(scores["relight_psnr_l"]) == 1 and len(scores["swap_truth_albedo_relight_psnr_l"]) == 1, scores
    assert scores["relight_psnr_l"][0] > 25.0

@pytest.mark.slow
def test_an_export_of_the_true_shape_relights_like_the_truth(renderer, tmp_path):
    environment = make_procedural_environment("sky", width=256)
    cameras = [Camera.from_fov(64, 64, 40.0, look_at((3.0 * np.cos(a), 3.0 * np.sin(a), 1.0), (0, 0, 0)))
               for a in np.radians([0.0, 120.0, 240.0])]
    material = PBRMaterial(base_color_factor=(*ORANGE, 1.0), roughness_factor=0.5, metallic_factor=0.0)
    truth = render_relight_truth(renderer, [uv_sphere(0.5, segments=96, material=material)], np.eye(4), cameras, [0, 1, 2],
                                 environment, 30.0, 0.0)
    # The pictures also show a second environment (studio), not scored.
    also = render_relight_truth(renderer, [uv_sphere(0.5, segments=96, material=material)], np.eye(4), cameras, [0, 1, 2],
                                make_procedural_environment("studio", width=256), 0.0, 0.0)
    obj = SimpleNamespace(name="sphere", relight=truth, relight_also=also, views=SimpleNamespace(cameras=cameras))
    pattern = _Plain(colour_a=ORANGE, colour_b=ORANGE, roughness_range=(0.5, 0.5))
    relighter = Relighter(RelightConfig(grid=64, faces=4000, texture=128), pictures=tmp_path / "pictures")
    try:
        right, wrong = {}, {}
        relighter.row = "true shape"
        relighter.score(SphereField(0.5, pattern=pattern), obj, [0, 1, 2], right)
        relighter.row = "shifted/smaller"
        relighter.score(SphereField(0.35, center=(0.1, 0.0, 0.0), pattern=pattern), obj, [0, 1, 2], wrong)
    finally:
        relighter.release()
    # The true shape and material, exported and read back in its own frame, relight as the truth does;
    # a smaller, shifted sphere does not.
    assert np.mean(right["relight_psnr_l"]) > 30.0, right
    assert np.mean(wrong["relight_psnr_l"]) < np.mean(right["relight_psnr_l"]) - 10.0, wrong
    # The pictures: per row and environment, the truth above the export on the three views; the true
    # shape's rows agree under both environments, and the two environments look different.
    import cv2

    assert sorted(p.name for p in (tmp_path / "pictures").iterdir()) == ["shifted_smaller__sphere.png", "true_shape__sphere.png"]
    for name, close in (("true_shape__sphere.png", True), ("shifted_smaller__sphere.png", False)):
        picture = cv2.imread(str(tmp_path / "pictures" / name)).astype(np.float64)
        # The title, then per environment a label and two rows of three square views.
        side = picture.shape[1] // 3
        assert picture.shape[0] == 3 * 22 + 4 * side
        first, second = picture[44:44 + 2 * side], picture[66 + 2 * side:]
        rows = np.split(first, 2) + np.split(second, 2)
        for truth_row, export_row in ((rows[0], rows[1]), (rows[2], rows[3])):
            assert (np.abs(truth_row - export_row).mean() < 4.0) == close, name
        assert np.abs(rows[0] - rows[2]).mean() > 4.0  # sky and studio


@pytest.mark.slow
def test_eval_reports_the_relighting_and_what_lit_and_relit_each_object(tmp_path, capsys):
    from lirm.engine.cli import main

    assert main(["eval", "--objects", "1", "--updates", "1", "--output-views", "1", "--size", "48",
                 "-o", str(tmp_path / "eval.md")]) == 0
    table = capsys.readouterr().out
    assert "Relighting test:" in table and "| PSNR-H ↑ | PSNR-L ↑ |" in table
    relight = table.split("Relighting test:")[1].strip().split("\n\n")[0].splitlines()
    assert len(relight) >= 3 and all(line.count("|") == relight[0].count("|") for line in relight), relight
    assert all("|  |" not in line for line in relight), relight  # no empty reconstructor cell
    assert "- vase#0: lit by studio (rotated" in table and "relit by sky (rotated" in table
    import json

    row = json.loads((tmp_path / "eval.json").read_text())["rows"][0]
    assert np.isfinite(row["relight_psnr_l"]) and np.isfinite(row["relight_psnr_h"])
