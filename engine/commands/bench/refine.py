"""`lirm bench refine`: refinement quality against its time budget."""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from ...errors import LirmUsageError
from ..common import (VIEW_SIZE, add_first_object_argument, add_gltf_set_arguments, bar_updater, check_first_object,
                      heldout_objects, model_with_warning, require_at_least_one, require_range, view_progress_bar)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("refine", help="refinement quality against its time budget (30 s, 1, 3, 10 min) on a held-out set, with peak memory")
    parser.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    parser.add_argument("--set", choices=("synthetic", "gltf"), default="synthetic", help="held-out set (default synthetic)")
    parser.add_argument("--objects", type=int, default=4, help="held-out synthetic objects (default 4)")
    add_first_object_argument(parser)
    parser.add_argument("--size", type=int, default=128, help="side of the protocol views and of the input crops (default 128)")
    parser.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    parser.add_argument("--minutes", type=float, nargs="+", default=[0.5, 1.0, 3.0, 10.0], help="budgets (default 0.5 1 3 10)")
    parser.add_argument("--steps", type=int, metavar="N",
                        help="instead of --minutes: each fit runs exactly N steps, its schedule following the steps alone, "
                             "so that the same inputs give the same fit twice on one machine (other CPUs round differently; "
                             "the output names the machine) and two settings compare at equal steps whatever its pace")
    parser.add_argument("--init", choices=("lirm", "hull", "hull-lirm", "scratch", "auto"), default="lirm",
                        help="start from (default lirm; hull-lirm: the hull's shape with LIRM's materials; auto: whichever "
                             "of the two agrees better with the inputs, as `lirm refine` starts a capture)")
    parser.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                        help="a refinement setting, e.g. losses.eikonal=0, edge_ray_fraction=0, plane_resolutions=(128,); repeatable")
    add_gltf_set_arguments(parser)
    parser.add_argument("--warm-start", action="store_true",
                        help="instead: refining again after new views, cold (from LIRM) for the first --minutes against warm "
                             "(from the earlier refinement) for 1/4, 1/2 and all of it")
    parser.add_argument("--materials", action="store_true", help="inverse-render the materials (as `lirm refine --materials`) "
                        "and also score roughness, metallic and the relighting test")
    parser.add_argument("--pictures", type=Path, help="with --materials: the relighting test's pictures, per budget and object")
    parser.add_argument("--lighting", choices=("estimate", "truth", "truth-panorama"), default="estimate",
                        help="with --materials: inverse-render under the capture-style estimate from the inputs' backgrounds "
                             "(default), or under the environment that really lit them (an oracle: what the estimate costs): "
                             "as the renderer's own tables (truth), or area-averaged into the fit's own 16 x 32 panorama "
                             "and held (truth-panorama: what the panorama costs as a representation)")
    parser.add_argument("--texture-fit", choices=("on", "off", "both", "variant"), default="on",
                        help="with --materials: the relighting test's export fits its textures to the input photos (on, as "
                             "`lirm export` does for a capture refined with materials), keeps the field's baked ones (off), "
                             "scores both exports of the same refined field (both: a paired ablation), or scores the fit "
                             "with its default settings and with the --fit-option changes (variant), each with its time")
    parser.add_argument("--fit-option", action="append", default=[], metavar="KEY=VALUE",
                        help="with --texture-fit variant: a texture-fit setting of the variant, e.g. metal_search=False, "
                             "footprint=1; repeatable")
    parser.add_argument("--swap-study", action="store_true",
                        help="with --materials: also relight the export with parts swapped for the truth's (albedo, all "
                             "materials, geometry, the albedo's detail or coarse colour): where the relighting error comes from")
    parser.add_argument("--json", type=Path, help="also write every object's numbers here")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.refine_bench import apply_options, dumps, refine_bench_table, run_refine_bench, texture_fit_variant
    from ...evaluation.evaluate import EvalConfig
    from ...io.atomic_files import atomic_write
    from ...refine.config import refine_preset

    require_at_least_one(args, "objects", "output_views")
    if args.pictures and not args.materials:
        raise LirmUsageError("--pictures shows the relighting test, which only --materials runs; add --materials")
    if args.lighting != "estimate" and not args.materials:
        raise LirmUsageError(f"--lighting {args.lighting} lights the inverse rendering, which only --materials runs; add --materials")
    if args.texture_fit != "on" and not args.materials:
        raise LirmUsageError("--texture-fit changes the relighting test's export, which only --materials runs; add --materials")
    if (args.texture_fit == "variant") != bool(args.fit_option):
        raise LirmUsageError("--texture-fit variant scores a texture fit with other settings: give them with --fit-option "
                             "KEY=VALUE (and --fit-option only with --texture-fit variant)")
    variant = texture_fit_variant(args.fit_option) if args.fit_option else None  # (its errors before any work)
    if args.swap_study and (not args.materials or args.warm_start):
        raise LirmUsageError("--swap-study takes apart the relighting test, which only --materials runs (and not with "
                             "--warm-start); add --materials")
    if args.lighting != "estimate" and args.warm_start:
        raise LirmUsageError(f"--lighting {args.lighting} is for the budget table, not --warm-start")
    require_range(args, "size", VIEW_SIZE, " pixels")
    check_first_object(args)
    if args.steps is not None and (args.steps < 1 or args.warm_start):
        raise LirmUsageError(f"--steps must be at least 1 (and is for the budget table, not --warm-start), got {args.steps}")
    if any(not m > 0 for m in args.minutes):
        raise LirmUsageError(f"--minutes must all be positive, got {args.minutes}")
    source = model_with_warning(args.checkpoint)
    base = apply_options(refine_preset("default", inverse_rendering=bool(args.materials)), args.option)
    args.updates = 4
    objects = heldout_objects(args)
    if args.warm_start:
        from ...bench.refine_bench import run_warm_start_bench, warm_start_table

        bar = view_progress_bar(len(objects), "warm and cold starts")
        try:
            result = run_warm_start_bench(source.model, objects, EvalConfig(output_views=args.output_views), base,
                                          args.minutes[0], progress=bar_updater(bar))
        finally:
            bar.close()
        table = warm_start_table(result)
    else:
        budgets = args.minutes
        if args.steps is not None:  # one fit of exactly that many steps, no time budget
            budgets, base = [None], replace(base, iterations=args.steps)
        bar = view_progress_bar(len(budgets), "refinement budgets")
        try:
            result = run_refine_bench(source.model, objects, EvalConfig(output_views=args.output_views), base, budgets,
                                      args.init, progress=bar_updater(bar), pictures=args.pictures,
                                      lighting_source=args.lighting, texture_fit=args.texture_fit,
                                      swap_study=args.swap_study,
                                      variant_fit=variant)
        finally:
            bar.close()
        table = refine_bench_table(result, args.set)
    result["options"] = args.option
    print(table)
    if args.json:
        atomic_write(args.json, lambda tmp: tmp.write_text(dumps(result), encoding="utf-8"))
    return 0
