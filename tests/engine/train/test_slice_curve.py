"""`lirm curve`: the slices' logs joined into one curve, on the repository's own logs and on made-up ones."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from lirm.engine.cli import main
from lirm.engine.train.slice_curve import curve_blocks, read_slices

REPO_LOGS = Path(__file__).resolve().parents[3] / "resources" / "checkpoints" / "training-logs" / "small"
METRICS = ["step", "loss", "colour", "albedo", "normal"]


def _slice(folder: Path, steps: range, loss: float, evals: dict[int, float] = {}) -> None:
    folder.mkdir(parents=True)
    with open(folder / "metrics.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(METRICS)
        w.writerows([s, loss, 0.1, 0.2, 0.3] for s in steps)
    with open(folder / "eval.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["step", "update", "psnr", "albedo_psnr"])
        for step, psnr in evals.items():
            w.writerows([[step, 1, psnr, psnr - 1], [step, 2, psnr + 5, 0]])


def test_slices_join_in_step_order_and_a_repeated_step_keeps_the_later_slice(tmp_path):
    _slice(tmp_path / "slice02-a", range(1, 8), 2.0, {5: 12.0})
    _slice(tmp_path / "slice03-b", range(6, 13), 1.0, {10: 14.0})  # steps 6-7 logged again by the next slice
    metrics, evals = read_slices(tmp_path)
    assert [int(r["step"]) for r in metrics] == list(range(1, 13))
    assert [r["slice"] for r in metrics[4:7]] == ["slice02", "slice03", "slice03"]
    first, second = curve_blocks(metrics, evals, block=5)[:2]
    assert (first.first_step, first.last_step, first.slices, first.mean_loss) == (1, 5, ["slice02"], 2.0)
    assert (first.eval_step, first.psnr_update1, first.albedo_psnr_update1) == (5, 12.0, 11.0)  # update 1, not 2
    assert second.slices == ["slice03"] and second.mean_loss == pytest.approx(1.0)  # steps 6-10: the later rows
    assert second.psnr_update1 == 14.0


def test_curve_of_the_repository_logs(tmp_path, capsys):
    assert main(["curve", str(REPO_LOGS), "--png", str(tmp_path / "curve.png")]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].startswith("| steps | slices | mean loss")
    assert table[2].startswith("| 1-200 | slice02")  # the first slice that brought weights back
    picture = cv2.imread(str(tmp_path / "curve.png"))
    assert picture.shape[0] > 100 and np.ptp(picture) > 100


def test_a_folder_without_slices_is_refused(tmp_path, capsys):
    assert main(["curve", str(tmp_path)]) != 0
    assert "no slice folders with a metrics.csv" in capsys.readouterr().err
    _slice(tmp_path / "slice05-started", range(0), 1.0)  # a slice stopped before its first step
    assert main(["curve", str(tmp_path)]) != 0
    assert "hold no steps yet" in capsys.readouterr().err
