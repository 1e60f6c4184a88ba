"""One training curve across GPU slices (issue 22): each slice keeps its own logs folder
(`resources/checkpoints/training-logs/<preset>/sliceNN-DATE-GPU/` with metrics.csv and eval.csv, see
gpu_slice.sh); this joins them in step order into the table the README and the model card show (mean
loss and held-out PSNR per block of steps) and one picture of the whole curve."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.images import write_png

from .loss_curve import draw_loss_curves, metrics_arrays


@dataclass
class CurveBlock:
    first_step: int
    last_step: int
    slices: list[str]
    mean_loss: float
    mean_colour: float
    eval_step: int | None  # the last held-out evaluation inside the block
    psnr_update1: float | None
    albedo_psnr_update1: float | None


def _rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def read_slices(logs_dir: Path) -> tuple[list[dict], list[dict]]:
    """Every slice's metrics and evaluation rows, each tagged with its slice, in step order. A step logged
    twice (a slice whose folder repeats an earlier one's rows) keeps the later slice's row."""
    folders = sorted(p for p in Path(logs_dir).iterdir() if p.is_dir() and (p / "metrics.csv").is_file()) \
        if Path(logs_dir).is_dir() else []
    if not folders:
        raise LirmUserError(f"{logs_dir}: no slice folders with a metrics.csv; point at a folder such as "
                            "resources/checkpoints/training-logs/small")
    metrics: dict[int, dict] = {}
    evals: dict[tuple[int, int], dict] = {}
    for folder in folders:
        for row in _rows(folder / "metrics.csv"):
            metrics[int(row["step"])] = {**row, "slice": folder.name.split("-")[0]}
        for row in _rows(folder / "eval.csv"):
            evals[(int(row["step"]), int(row["update"]))] = row
    if not metrics:
        raise LirmUserError(f"{logs_dir}: the slices' metrics.csv files hold no steps yet")
    return [metrics[s] for s in sorted(metrics)], [evals[k] for k in sorted(evals)]


def curve_blocks(metrics: list[dict], evals: list[dict], block: int = 200) -> list[CurveBlock]:
    blocks = []
    last = int(metrics[-1]["step"])
    for start in range(1, last + 1, block):
        end = start + block - 1
        rows = [r for r in metrics if start <= int(r["step"]) <= end]
        if not rows:
            continue
        first_updates = [e for e in evals if start <= int(e["step"]) <= end and int(e["update"]) == 1]
        latest = first_updates[-1] if first_updates else None
        blocks.append(CurveBlock(
            first_step=int(rows[0]["step"]), last_step=int(rows[-1]["step"]),
            slices=sorted({r["slice"] for r in rows}),
            mean_loss=float(np.mean([float(r["loss"]) for r in rows])),
            mean_colour=float(np.mean([float(r["colour"]) for r in rows])),
            eval_step=int(latest["step"]) if latest else None,
            psnr_update1=float(latest["psnr"]) if latest else None,
            albedo_psnr_update1=float(latest["albedo_psnr"]) if latest else None))
    return blocks


def markdown_curve(blocks: list[CurveBlock]) -> str:
    lines = ["| steps | slices | mean loss | mean colour loss | held-out PSNR after update 1 | albedo PSNR | at step |",
             "|---|---|---|---|---|---|---|"]
    for b in blocks:
        psnr = f"{b.psnr_update1:.2f}" if b.psnr_update1 is not None else "-"
        albedo = f"{b.albedo_psnr_update1:.2f}" if b.albedo_psnr_update1 is not None else "-"
        lines.append(f"| {b.first_step}-{b.last_step} | {', '.join(b.slices)} | {b.mean_loss:.3f} | {b.mean_colour:.4f} | "
                     f"{psnr} | {albedo} | {b.eval_step or '-'} |")
    return "\n".join(lines) + "\n"


def write_curve_picture(metrics: list[dict], out_png: Path, title: str) -> Path:
    write_png(out_png, draw_loss_curves(metrics_arrays(metrics), ["loss", "colour", "albedo", "normal"], title=title))
    return out_png
