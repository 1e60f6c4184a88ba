"""`lirm bench refine`: refinement quality against its time budget on a held-out set, with the peak
memory of each fit, and the ablations of its settings (`--option losses.eikonal=0`, ...).

Each budget refines every object from the same start on the same 16 input views (the protocol's 4
input sets) and scores the same output views; the table gives the means, the JSON every object.
"""

from __future__ import annotations

import ast
import json
from dataclasses import asdict, fields, replace
from pathlib import Path

import numpy as np

from lirm.engine.evaluation.evaluate import EvalConfig
from lirm.engine.evaluation.heldout_sets import HeldoutObject
from lirm.engine.evaluation.evaluate import score_field, update_scores
from lirm.engine.evaluation.relight_swaps import EXPORTED_MATERIAL_KEYS, SWAPS
from lirm.engine.evaluation.refined_rows import RELIGHT_KEYS, lirm_field, mean_of, per_object_scores, refine_inputs
from lirm.engine.refine import initial_fields
from lirm.engine.refine.refinable_field import RefinableField
from lirm.engine.refine.refiner import refine_field
from lirm.engine.errors import LirmUserError
from lirm.engine.export.photo_texture_fit import TextureFitConfig
from lirm.engine.refine.config import LossWeights, RefineConfig

from .machine_facts import describe, machine_facts
from .peak_memory import PeakMemory, release_memory


SWAP_KEYS = tuple(f"swap_{name}_relight_psnr_{kind}" for name in SWAPS for kind in ("l", "h")) + EXPORTED_MATERIAL_KEYS


def _literal(option: str, flag: str, example: str) -> tuple[str, object]:
    """KEY and its Python-literal VALUE (numbers, tuples, True/False) from `flag`'s KEY=VALUE."""
    key, sep, text = option.partition("=")
    if not sep:
        raise LirmUserError(f"{flag} {option!r}: write KEY=VALUE, e.g. {example}")
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        raise LirmUserError(f"{flag} {option!r}: {text!r} is not a number, tuple or True/False") from None
    return key, tuple(value) if isinstance(value, list) else value


# Settings whose value is text (a path, a choice): their VALUE is taken as written, quotes optional,
# so that `--option material_net=/path/net.safetensors` needs no Python quoting.
TEXT_SETTINGS = frozenset(f.name for f in fields(RefineConfig) if isinstance(getattr(RefineConfig(), f.name), str))


def apply_options(config: RefineConfig, options: list[str]) -> RefineConfig:
    """KEY=VALUE settings onto a RefineConfig; `losses.NAME=W` sets a loss weight. Values are Python
    literals (numbers, tuples), or text for the text settings (TEXT_SETTINGS)."""
    for option in options:
        key, sep, text = option.partition("=")
        if sep and key in TEXT_SETTINGS:
            try:
                config = replace(config, **{key: text.strip().strip("'\"")})
            except ValueError as error:
                raise LirmUserError(f"--option {option!r}: {error}") from None
            continue
        key, value = _literal(option, "--option", "losses.eikonal=0 or plane_resolutions=(128,)")
        if key.startswith("losses."):
            name = key[len("losses."):]
            if name not in {f.name for f in fields(LossWeights)}:
                raise LirmUserError(f"--option {option!r}: no loss term {name!r}; terms: {', '.join(f.name for f in fields(LossWeights))}")
            config = replace(config, losses=replace(config.losses, **{name: float(value)}))
        else:
            if key not in {f.name for f in fields(RefineConfig)} or key == "losses":
                raise LirmUserError(f"--option {option!r}: no setting {key!r}; settings: "
                                    f"{', '.join(f.name for f in fields(RefineConfig) if f.name != 'losses')}")
            if key == "plane_resolutions" and isinstance(value, int):
                value = (value,)
            config = replace(config, **{key: value})
    return config


def texture_fit_variant(options: list[str]) -> TextureFitConfig:
    """The texture fit's default settings with KEY=VALUE changes (`--fit-option`)."""
    names = {f.name for f in fields(TextureFitConfig)}
    changes = {}
    for option in options:
        key, value = _literal(option, "--fit-option", "metal_search=False")
        if key not in names:
            raise LirmUserError(f"--fit-option {option!r}: no texture-fit setting {key!r}; settings: {', '.join(sorted(names))}")
        changes[key] = value
    try:
        return TextureFitConfig(**changes)
    except (TypeError, ValueError) as error:
        raise LirmUserError(f"--fit-option {' '.join(options)}: {error}") from None


def budget_label(minutes: float | None, config: RefineConfig) -> str:
    """A budget as the tables print it: minutes of wall clock, or a fixed count of steps (minutes None)."""
    return f"{minutes:g} min" if minutes is not None else f"{config.iterations} steps"


def run_refine_bench(model, objects: list[HeldoutObject], eval_config: EvalConfig, base: RefineConfig, minutes: list[float | None],
                     init: str, progress=None, pictures: Path | None = None, lighting_source: str = "estimate",
                     texture_fit: str = "on", swap_study: bool = False, variant_fit: TextureFitConfig | None = None) -> dict:
    """With base.inverse_rendering, also the material and relighting scores (and, with `pictures`,
    the relighting test's pictures there); `lighting_source` (refined_rows.LIGHTING_SOURCES): the
    estimate from the inputs' backgrounds, or an oracle lit by their true environment; `texture_fit`: "on", the relighting
    test's export fits its textures to the input photos (RelightConfig.fit_textures), "off", "both"
    (the baked export scored too, under baked_ keys) or "variant" (the fit with the settings
    `variant_fit` scored too, under variant_ keys; both fits' seconds as fit_seconds); `swap_study`:
    also the relighting with parts swapped for the truth's (relight_swaps.py; the objects must carry
    the truth's G-buffers), under swap_ keys. A budget of None
    runs base.iterations steps with no wall-clock budget: the schedule then follows the steps alone, and
    the fit is the same twice on one machine (with a wall-clock budget it follows the time, even at step
    0); across machines it differs in the last bits and then more (machine_facts.py), so the result
    records the machine."""
    meter = PeakMemory("cpu" if base.device == "cpu" else "cuda")
    budgets = []
    relighter = None
    if base.inverse_rendering:
        from lirm.engine.evaluation.relighting import RelightConfig, Relighter

        if texture_fit == "variant" and variant_fit is None:
            raise ValueError("texture_fit 'variant' needs the variant's settings (variant_fit)")
        relighter = Relighter(RelightConfig(fit_textures=texture_fit != "off", also_baked=texture_fit == "both",
                                            variant_fit=variant_fit if texture_fit == "variant" else None,
                                            swap_study=swap_study),
                              pictures=pictures)
    paired = {"both": "baked_", "variant": "variant_"}.get(texture_fit)
    timed = ("fit_seconds",) + (("variant_fit_seconds",) if texture_fit == "variant" else ()) if texture_fit != "off" else ()
    keys = ("psnr", "ssim", "lpips", "albedo_psnr", "roughness_psnr", "metallic_psnr", "chamfer", "seconds", "steps") + (
        RELIGHT_KEYS + ("relight_lpips",) + timed if relighter else ()) + (tuple(f"{paired}{k}" for k in RELIGHT_KEYS) if paired else ()) + (
        SWAP_KEYS if swap_study else ())
    try:
        for k, budget in enumerate(minutes):
            label = budget_label(budget, base)
            if progress:
                progress(label, k, len(minutes))
            config = replace(base, minutes=budget)
            if relighter is not None:
                relighter.row = f"{init} {label}"
            release_memory(meter.device)
            meter.reset()
            rows = per_object_scores(model, objects, eval_config, config, init, relighter, lighting_source)
            budgets.append({"minutes": budget, "budget": label, "peak_bytes": meter.peak(), "objects": rows, **{key: mean_of(rows, key) for key in keys}})
        if progress:
            progress("done", len(minutes), len(minutes))
    finally:
        if relighter is not None:
            relighter.release()
    variant = {"variant_fit": asdict(variant_fit)} if texture_fit == "variant" and variant_fit is not None else {}
    return {"init": init, "lighting": lighting_source, "texture_fit": texture_fit, **variant,
            "settings": base.to_dict(),
            "machine": machine_facts(base.device),
            "memory_method": meter.method, "budgets": budgets}


def refine_bench_table(result: dict, set_name: str) -> str:
    first = result["budgets"][0]["objects"] if result["budgets"] else []
    lit = {"truth": " under the inputs' true lighting (oracle)",
           "truth-panorama": " under the inputs' true lighting as the fit's own panorama, held (oracle)"}.get(result.get("lighting"), "")
    lines = [f"Refinement from {result['init']}{lit} on the {set_name} set, {len(first)} objects "
             f"({', '.join(r['object'] for r in first)}); means over objects:", "",
             "| budget | PSNR ↑ | SSIM ↑ | LPIPS ↓ | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ | CD ↓ | steps | seconds "
             "| peak memory (GB) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for b in result["budgets"]:
        lines.append(f"| {b['budget']} | {b['psnr']:.2f} | {b['ssim']:.3f} | {_optional(b.get('lpips'), 3)} | {b['albedo_psnr']:.2f} | {b['roughness_psnr']:.2f} | "
                     f"{b['metallic_psnr']:.2f} | {b['chamfer']:.4f} | {b['steps']:.0f} | {b['seconds']:.0f} | "
                     f"{b['peak_bytes'] / 1e9:.2f} |")
    if result["budgets"] and not _computed(result["budgets"][0].get("lpips")):
        from lirm.engine.evaluation.evaluate import METRIC_NETWORK
        from lirm.engine.perceptual.lpips_weights import missing_weights_reason

        lines += ["", f"LPIPS skipped: {missing_weights_reason(METRIC_NETWORK) or 'no view was scored'}."]
    if result["budgets"] and "relight_psnr_l" in result["budgets"][0]:
        lines += ["", "The relighting test (materials inverse-rendered):", ""] + _relight_rows(result, "")
        variant = ", ".join(f"{k}={v}" for k, v in _variant_changes(result).items()) or "the default settings"
        for prefix, what in (("baked_", "with the field's baked textures, not fitted to the photos"),
                             ("variant_", f"with the textures fitted with {variant}")):
            if f"{prefix}relight_psnr_l" in result["budgets"][0]:
                lines += ["", f"The same refined fields exported {what}:", ""] + _relight_rows(result, prefix)
    if result["budgets"] and "swap_export_relight_psnr_l" in result["budgets"][0]:
        lines += ["", "Where the relighting error comes from (the export relit with parts swapped for the truth's; "
                  "relight_swaps.py), PSNR-L / PSNR-H:", "",
                  "| budget | " + " | ".join(SWAPS) + " |", "|---|" + "---|" * len(SWAPS)]
        for b in result["budgets"]:
            lines.append(f"| {b['budget']} | " + " | ".join(
                f"{b[f'swap_{name}_relight_psnr_l']:.2f} / {b[f'swap_{name}_relight_psnr_h']:.2f}" for name in SWAPS) + " |")
        lines += ["", "The export's own materials against the truth's (its G-buffers from the same output views; the table "
                  "above scores the refined field's):", "",
                  "| budget | albedo PSNR ↑ | roughness PSNR ↑ | metallic PSNR ↑ |", "|---|---|---|---|"]
        for b in result["budgets"]:
            lines.append(f"| {b['budget']} | " + " | ".join(f"{b[key]:.2f}" for key in EXPORTED_MATERIAL_KEYS) + " |")
    heard = [r["object"] for r in first if "material network used" in r.get("material_network", "")]
    if any(r.get("material_network") for r in first):
        lines += ["", f"The material network was heard on {len(heard)} of {len(first)} objects"
                  f"{': ' + ', '.join(heard) if heard else ''} (model/material_net_familiarity.py)."]
    if "machine" in result:  # fits of equal steps pair exactly only on one machine (machine_facts.py)
        lines += ["", f"Machine: {describe(result['machine'])}."]
    return "\n".join(lines) + "\n"


def _relight_rows(result: dict, prefix: str) -> list[str]:
    """The relighting table's rows of `prefix`-ed scores, with the texture fit's seconds where it ran."""
    timed = f"{prefix}fit_seconds" in result["budgets"][0]
    perceptual = f"{prefix}relight_lpips" in result["budgets"][0]
    lines = ["| budget | relight PSNR-H ↑ | relight PSNR-L ↑ |" + (" relight LPIPS ↓ |" if perceptual else "")
             + (" texture fit (s) |" if timed else ""),
             "|---|---|---|" + ("---|" if perceptual else "") + ("---|" if timed else "")]
    for b in result["budgets"]:
        lines.append(f"| {b['budget']} | {b[prefix + 'relight_psnr_h']:.2f} | {b[prefix + 'relight_psnr_l']:.2f} |"
                     + (f" {_optional(b[prefix + 'relight_lpips'], 3)} |" if perceptual else "")
                     + (f" {b[prefix + 'fit_seconds']:.1f} |" if timed else ""))
    return lines


def _computed(value) -> bool:
    """Whether a figure was computed (LPIPS is None, or NaN after a JSON round trip, without its weights)."""
    return value is not None and bool(np.isfinite(value))


def _optional(value, digits: int) -> str:
    """A figure, or "-" where it was not computed."""
    return f"{value:.{digits}f}" if _computed(value) else "-"


def _variant_changes(result: dict) -> dict:
    """The settings in which the variant texture fit differs from the default one."""
    default = asdict(TextureFitConfig())
    return {k: v for k, v in result.get("variant_fit", {}).items() if default.get(k) != v}


def dumps(result: dict) -> str:
    return json.dumps(result, indent=1, default=lambda v: float(v) if isinstance(v, np.floating) else str(v))


def _scored(field, obj: HeldoutObject, eval_config: EvalConfig) -> dict:
    import torch

    outputs = obj.protocol.outputs[:eval_config.output_views] if eval_config.output_views else obj.protocol.outputs
    scores: dict[str, list[float]] = {}
    with torch.no_grad():
        score_field(field, obj, outputs, eval_config, scores)
    row = update_scores(4, scores).to_dict()
    return {k: row[k] for k in ("psnr", "ssim", "albedo_psnr", "chamfer")}


def run_warm_start_bench(model, objects: list[HeldoutObject], eval_config: EvalConfig, base: RefineConfig, minutes: float,
                         fractions: tuple[float, ...] = (0.25, 0.5, 1.0), progress=None) -> dict:
    """The progressive case: a user refined after 2 updates (8 views); 8 more views arrive and update 4
    runs. Refining again cold (from LIRM's update 4) for `minutes` is compared with going on from the
    first refinement (warm) for shares of that time, on all 16 views."""
    from lirm.engine.reconstruction.refine_step import warm_start_schedule

    rows = []
    for k, obj in enumerate(objects):
        if progress:
            progress(obj.name, k, len(objects))
        radius = model.config.radius
        sets = obj.protocol.input_sets
        early = refine_inputs(obj, [i for s in sets[:2] for i in s])
        views = refine_inputs(obj, [i for s in sets[:4] for i in s])
        first = refine_field(initial_fields.from_lirm(lirm_field(model, obj, 2), base.plane_resolutions[0]), early,
                             replace(base, minutes=minutes), initial_fields.views_sampling_grid(early, base, radius),
                             start_has_materials=True)
        grid = initial_fields.views_sampling_grid(views, base, radius)
        cold = refine_field(initial_fields.from_lirm(lirm_field(model, obj, 4), base.plane_resolutions[0]), views,
                            replace(base, minutes=minutes), grid, start_has_materials=True)
        row = {"object": obj.name, "cold": {"minutes": minutes, **_scored(cold.field.frozen_field(), obj, eval_config)}, "warm": []}
        for share in fractions:
            start = RefinableField.from_field(first.field.frozen_field())
            warm = refine_field(start, views, warm_start_schedule(replace(base, minutes=minutes * share)), grid,
                                start_has_materials=True)
            row["warm"].append({"minutes": minutes * share, **_scored(warm.field.frozen_field(), obj, eval_config)})
        rows.append(row)
    if progress:
        progress("done", len(objects), len(objects))
    return {"minutes": minutes, "fractions": list(fractions), "objects": rows}


def warm_start_table(result: dict) -> str:
    objects = result["objects"]
    lines = [f"Refining again after 8 more views (update 4): cold from LIRM for {result['minutes']:g} min against warm from "
             f"the refinement after update 2; {len(objects)} objects, means:", "",
             "| start | minutes | PSNR ↑ | SSIM ↑ | CD ↓ |", "|---|---|---|---|---|"]
    mean = lambda items, key: float(np.mean([i[key] for i in items]))  # noqa: E731
    cold = [o["cold"] for o in objects]
    lines.append(f"| cold (LIRM update 4) | {result['minutes']:g} | {mean(cold, 'psnr'):.2f} | {mean(cold, 'ssim'):.3f} | {mean(cold, 'chamfer'):.4f} |")
    for k, share in enumerate(result["fractions"]):
        warm = [o["warm"][k] for o in objects]
        lines.append(f"| warm (refinement 1) | {result['minutes'] * share:g} | {mean(warm, 'psnr'):.2f} | {mean(warm, 'ssim'):.3f} | "
                     f"{mean(warm, 'chamfer'):.4f} |")
    return "\n".join(lines) + "\n"
