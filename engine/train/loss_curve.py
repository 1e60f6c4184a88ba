"""A picture of a run's loss curves from metrics.csv (cv2 only: no plotting library is installed).

Raw values in light colours, a moving average on top; one curve per chosen column, log-scaled y.
`lirm train` writes it beside metrics.csv at the end of every run."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import cv2
import numpy as np

from lirm.engine.io.images import write_png

COLOURS = [(200, 80, 30), (40, 140, 40), (30, 60, 200), (150, 40, 150), (20, 150, 200), (120, 120, 120)]


def read_metrics(path: Path) -> dict[str, np.ndarray]:
    with open(path, newline="") as f:
        return metrics_arrays(list(csv.DictReader(f)))


def metrics_arrays(rows: list[dict]) -> dict[str, np.ndarray]:
    """metrics.csv rows as one float array per numeric column (empty cells NaN; text columns left out)."""
    if not rows:
        return {}
    out = {}
    for key in rows[0]:
        try:
            out[key] = np.array([float(r[key]) if r[key] not in ("", None) else np.nan for r in rows])
        except ValueError:
            continue
    return out


def _smooth(y: np.ndarray, window: int) -> np.ndarray:
    if len(y) < 2 or window <= 1:
        return y
    kernel = np.ones(window) / window
    padded = np.concatenate([np.full(window - 1, y[0]), y])
    return np.convolve(padded, kernel, mode="valid")


def draw_loss_curves(metrics: dict[str, np.ndarray], columns: list[str], size: tuple[int, int] = (900, 500),
                     title: str = "") -> np.ndarray:
    w, h = size
    left, right, top, bottom = 70, 20, 40, 40
    image = np.full((h, w, 3), 255, np.uint8)
    steps = metrics["step"]
    curves = [(c, metrics[c]) for c in columns if c in metrics and np.isfinite(metrics[c]).any()]
    values = np.concatenate([y[np.isfinite(y) & (y > 0)] for _, y in curves]) if curves else np.array([1.0])
    lo, hi = math.floor(math.log10(values.min())), math.ceil(math.log10(values.max()))
    hi = max(hi, lo + 1)

    def to_px(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        xs = left + (x - steps.min()) / max(steps.max() - steps.min(), 1) * (w - left - right)
        ys = top + (hi - np.log10(np.maximum(y, 10.0**lo))) / (hi - lo) * (h - top - bottom)
        return np.stack([xs, ys], -1).round().astype(np.int32)

    cv2.rectangle(image, (left, top), (w - right, h - bottom), (0, 0, 0), 1)
    for e in range(lo, hi + 1):
        y = int(top + (hi - e) / (hi - lo) * (h - top - bottom))
        cv2.line(image, (left, y), (w - right, y), (225, 225, 225), 1)
        cv2.putText(image, f"1e{e}", (8, y + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    for frac in (0.0, 0.5, 1.0):
        step = steps.min() + frac * (steps.max() - steps.min())
        x = int(left + frac * (w - left - right))
        cv2.putText(image, f"{step:.0f}", (x - 15, h - bottom + 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    window = max(1, len(steps) // 30)
    for k, (name, y) in enumerate(curves):
        colour = COLOURS[k % len(COLOURS)]
        light = tuple(int(c + (255 - c) * 0.7) for c in colour)
        finite = np.isfinite(y)
        cv2.polylines(image, [to_px(steps[finite], y[finite])], False, light, 1, cv2.LINE_AA)
        cv2.polylines(image, [to_px(steps[finite], _smooth(y[finite], window))], False, colour, 2, cv2.LINE_AA)
        cv2.putText(image, name, (left + 10 + 130 * k, top - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1, cv2.LINE_AA)
    if title:
        cv2.putText(image, title, (left, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    return image


def write_loss_curves(metrics_csv: Path, out_png: Path, columns: list[str] | None = None, title: str = "") -> Path | None:
    metrics = read_metrics(metrics_csv)
    if "step" not in metrics or len(metrics["step"]) < 2:
        return None
    columns = columns or ["loss", "colour", "albedo", "normal", "perceptual", "roughness"]
    return write_png(out_png, draw_loss_curves(metrics, columns, title=title))
