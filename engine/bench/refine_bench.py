"""`lirm bench refine`: refinement quality against its time budget on a held-out set, with the peak
memory of each fit, and the ablations of its settings (`--option losses.eikonal=0`, ...).

Each budget refines every object from the same start on the same 16 input views (the protocol's 4
input sets) and scores the same output views; the table gives the means, the JSON every object.
"""

from __future__ import annotations

import ast
import json
from dataclasses import fields, replace

import numpy as np

from lirm.engine.evaluation.evaluate import EvalConfig
from lirm.engine.evaluation.heldout_sets import HeldoutObject
from lirm.engine.evaluation.refined_rows import mean_of, per_object_scores
from lirm.engine.errors import LirmUserError
from lirm.engine.refine.config import LossWeights, RefineConfig

from .peak_memory import PeakMemory, release_memory


def apply_options(config: RefineConfig, options: list[str]) -> RefineConfig:
    """KEY=VALUE settings onto a RefineConfig; `losses.NAME=W` sets a loss weight. Values are Python
    literals (numbers, tuples)."""
    for option in options:
        key, sep, text = option.partition("=")
        if not sep:
            raise LirmUserError(f"--option {option!r}: write KEY=VALUE, e.g. losses.eikonal=0 or plane_resolutions=(128,)")
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            raise LirmUserError(f"--option {option!r}: {text!r} is not a number or tuple") from None
        if key.startswith("losses."):
            name = key[len("losses."):]
            if name not in {f.name for f in fields(LossWeights)}:
                raise LirmUserError(f"--option {option!r}: no loss term {name!r}; terms: {', '.join(f.name for f in fields(LossWeights))}")
            config = replace(config, losses=replace(config.losses, **{name: float(value)}))
        else:
            if key not in {f.name for f in fields(RefineConfig)} or key == "losses":
                raise LirmUserError(f"--option {option!r}: no setting {key!r}; settings: "
                                    f"{', '.join(f.name for f in fields(RefineConfig) if f.name != 'losses')}")
            if isinstance(value, list):
                value = tuple(value)
            if key == "plane_resolutions" and isinstance(value, int):
                value = (value,)
            config = replace(config, **{key: value})
    return config


def run_refine_bench(model, objects: list[HeldoutObject], eval_config: EvalConfig, base: RefineConfig, minutes: list[float],
                     init: str, progress=None) -> dict:
    meter = PeakMemory("cpu" if base.device == "cpu" else "cuda")
    budgets = []
    for k, budget in enumerate(minutes):
        if progress:
            progress(f"{budget:g} min", k, len(minutes))
        config = replace(base, minutes=budget)
        release_memory(meter.device)
        meter.reset()
        rows = per_object_scores(model, objects, eval_config, config, init)
        budgets.append({"minutes": budget, "peak_bytes": meter.peak(), "objects": rows,
                        **{key: mean_of(rows, key) for key in ("psnr", "ssim", "albedo_psnr", "chamfer", "seconds", "steps")}})
    if progress:
        progress("done", len(minutes), len(minutes))
    return {"init": init, "settings": base.to_dict(), "memory_method": meter.method, "budgets": budgets}


def refine_bench_table(result: dict, set_name: str) -> str:
    first = result["budgets"][0]["objects"] if result["budgets"] else []
    lines = [f"Refinement from {result['init']} on the {set_name} set, {len(first)} objects "
             f"({', '.join(r['object'] for r in first)}); means over objects:", "",
             "| budget (min) | PSNR ↑ | SSIM ↑ | albedo PSNR ↑ | CD ↓ | steps | seconds | peak memory (GB) |",
             "|---|---|---|---|---|---|---|---|"]
    for b in result["budgets"]:
        lines.append(f"| {b['minutes']:g} | {b['psnr']:.2f} | {b['ssim']:.3f} | {b['albedo_psnr']:.2f} | {b['chamfer']:.4f} | "
                     f"{b['steps']:.0f} | {b['seconds']:.0f} | {b['peak_bytes'] / 1e9:.2f} |")
    return "\n".join(lines) + "\n"


def dumps(result: dict) -> str:
    return json.dumps(result, indent=1, default=lambda v: float(v) if isinstance(v, np.floating) else str(v))
