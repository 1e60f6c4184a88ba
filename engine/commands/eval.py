"""`lirm eval`: the paper's metrics on a held-out set."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import LirmUsageError
from .common import (MESH_RESOLUTION, VIEW_SIZE, add_first_object_argument, add_gltf_set_arguments, bar_updater, check_first_object, heldout_objects,
                     model_with_warning, require_at_least_one, require_range, view_progress_bar)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("eval", help="the paper's metrics after updates 1-4 on a held-out set, as a Markdown table")
    parser.add_argument("checkpoint", type=Path, nargs="?", help="model weights (.safetensors), e.g. a training checkpoint (default: the shipped checkpoint)")
    parser.add_argument("--set", default="synthetic", help="synthetic (default), gltf, or a capture folder")
    parser.add_argument("--objects", type=int, default=4, help="objects of the synthetic set (default 4)")
    add_first_object_argument(parser)
    parser.add_argument("--size", type=int, default=128, help="side of the protocol views in pixels (default 128)")
    parser.add_argument("--updates", type=int, default=4, help="updates to score (default 4)")
    parser.add_argument("--output-views", type=int, help="score at most this many output views per object (default: all 12)")
    add_gltf_set_arguments(parser)
    parser.add_argument("--mesh-resolution", type=int, default=96, help="marching-cubes grid for the Chamfer distance (default 96)")
    parser.add_argument("--baselines", action="store_true",
                        help="also score, on the same views, the untrained network of the same architecture, a sphere of the inputs' "
                             "mean colour and the carved visual hull coloured from the views (no learning)")
    parser.add_argument("--refine", action="store_true",
                        help="also refine after the last update on the same input views: the rows 'refined from LIRM' and "
                             "'refined from the hull', with the seconds each took")
    parser.add_argument("--refine-minutes", type=float, help="time budget of each refinement (default: lirm refine's, 3 minutes)")
    parser.add_argument("--materials", action="store_true",
                        help="the refined rows inverse-render the materials (as `lirm refine --materials`), under the lighting "
                             "estimated from the input views' backgrounds")
    parser.add_argument("--no-relight", action="store_true",
                        help="skip the relighting test (each row's .glb export rendered under an environment that lit none "
                             "of the inputs; about 10 s per object and row on 2 cores)")
    parser.add_argument("--pictures", type=Path, help="write the relighting test's pictures here: per row and object, the truth "
                        "under the relighting environment above the relit export, on three output views, and the same under a "
                        "second environment that lit none of the inputs either (the synthetic set; the glTF set with 3 or more HDRIs)")
    parser.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..evaluation.baselines import MeanColourSphere, untrained_model
    from ..evaluation.carved_hull import CarvedHull
    from ..evaluation.evaluate import EvalConfig

    require_at_least_one(args, "objects", "updates", "output_views")
    if args.pictures and args.no_relight:
        raise LirmUsageError("--pictures shows the relighting test, which --no-relight skips; leave one of them out")
    require_range(args, "size", VIEW_SIZE, " pixels")
    check_first_object(args)
    require_range(args, "mesh_resolution", MESH_RESOLUTION, " samples per side")
    source = model_with_warning(args.checkpoint)
    model = source.model
    config = EvalConfig(updates=args.updates, output_views=args.output_views, mesh_resolution=args.mesh_resolution)
    objects = heldout_objects(args)
    training = source.extra.get("training", {})
    label = (args.checkpoint.name if args.checkpoint else source.description) + (
        f" (stage {training['stage']}, step {training['step']})" if training else "")
    contenders = [(label, model)]
    if args.baselines:
        contenders += [(f"untrained '{model.config.name}' (seed 0)", untrained_model(model.config)),
                       ("mean-colour sphere", MeanColourSphere(model.config.image_size, model.config.radius)),
                       ("carved visual hull", CarvedHull(model.config.image_size, radius=model.config.radius))]
    results = []
    relighter = None
    if not args.no_relight and any(o.relight is not None for o in objects):
        from ..evaluation.relighting import Relighter

        relighter = Relighter(pictures=args.pictures)
    try:
        _evaluate_contenders(args, contenders, objects, config, model, relighter, results)
    finally:
        if relighter is not None:
            relighter.release()
    return _write_eval(args, results, label, model, objects, contenders, source)


def _evaluate_contenders(args, contenders, objects, config, model, relighter, results) -> None:
    from ..evaluation.evaluate import evaluate_heldout

    for name, reconstructor in contenders:
        if relighter is not None:
            relighter.row = name
        bar = view_progress_bar(len(objects), f"evaluating {name}")
        bar.unit = "object"
        try:
            results.append((name, evaluate_heldout(reconstructor, objects, config, set_name=args.set, progress=bar_updater(bar),
                                                   relighter=relighter)))
        finally:
            bar.close()
    if args.refine:
        from ..evaluation.refined_rows import evaluate_refined
        from ..refine.config import refine_preset

        if args.refine_minutes is not None and not args.refine_minutes > 0:
            raise LirmUsageError(f"--refine-minutes must be positive, got {args.refine_minutes}")
        refine = refine_preset("default", inverse_rendering=bool(args.materials),
                               **({"minutes": args.refine_minutes} if args.refine_minutes else {}))
        for name, init in (("refined from LIRM", "lirm"), ("refined from the hull", "hull")):
            if relighter is not None:
                relighter.row = name
            bar = view_progress_bar(len(objects), f"{name} ({refine.minutes:g} min each)")
            bar.unit = "object"
            try:
                results.append((name, evaluate_refined(model, objects, config, refine, init, set_name=args.set,
                                                       progress=bar_updater(bar), relighter=relighter)))
            finally:
                bar.close()


def _write_eval(args, results, label, model, objects, contenders, source) -> int:
    from ..evaluation.report import comparison_table, markdown_table
    from ..io.atomic_files import atomic_write, atomic_write_json

    if len(results) == 1:
        table = markdown_table(results[0][1], f"{label}: '{model.config.name}' model")
    else:
        table = comparison_table(results, f"'{model.config.name}' model against the baselines")
    sensitivity = {}
    if len(objects) > 1 and all(o.surface is not None for o in objects):
        from ..evaluation.input_sensitivity import input_sensitivity

        lines = ["", "Input sensitivity (prediction at an object's surface from its own first views vs another object's; "
                     "about 0 = the inputs are ignored):", "", "| reconstructor | albedo Δ | SDF Δ |", "|---|---|---|"]
        for name, reconstructor in contenders:
            s = input_sensitivity(reconstructor, objects)
            sensitivity[name] = {"albedo": s.albedo, "sdf": s.sdf, "pairs": s.pairs}
            lines.append(f"| {name} | {s.albedo:.4f} | {s.sdf:.4f} |")
        table += "\n".join(lines) + "\n"
    print(table)
    if args.out:
        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), {
            "checkpoint": str(args.checkpoint) if args.checkpoint else source.description,
            **results[0][1].to_dict(),
            "baselines": {name: result.to_dict() for name, result in results[1:]}, "input_sensitivity": sensitivity})
    return 0
