"""`lirm bench trajectory`: the camera-trajectory study (guided, random, sequential)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ...errors import LirmUsageError
from ..common import (MESH_RESOLUTION, VIEW_SIZE, bar_updater, model_with_warning, require_at_least_one, require_range,
                      view_progress_bar)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("trajectory", help="next views chosen by guidance, at random or sequentially: quality after updates 2 and 3 (held-out synthetic set)")
    parser.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    parser.add_argument("--objects", type=int, default=4, help="held-out synthetic objects (default 4)")
    parser.add_argument("--size", type=int, default=64, help="side of the protocol views in pixels (default 64)")
    parser.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    parser.add_argument("--mesh-resolution", type=int, default=48, help="marching-cubes grid for guidance and the Chamfer distance (default 48)")
    parser.add_argument("--coverage-only", action="store_true", help="guided views by coverage alone, without the model's uncertainty (an ablation)")
    parser.add_argument("--binary-coverage", action="store_true",
                        help="guided views by binary coverage (seen within 60° or not) instead of viewing quality (an ablation)")
    parser.add_argument("--reconstructor", choices=("lirm", "carved-hull"), default="lirm",
                        help="what reconstructs: the LIRM model (default) or the carved visual hull coloured from the views, "
                             "a reconstructor without learning whose quality comes only from the views it gets")
    parser.add_argument("--input-size", type=int, default=64, help="the carved hull's input views in pixels (default 64, as the shipped tiny model's)")
    parser.add_argument("--random-draws", type=int, default=5, help="random choices per object; random's score is their mean (default 5)")
    parser.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import time

    from ...evaluation.evaluate import EvalConfig
    from ...evaluation.heldout_sets import synthetic_heldout
    from ...evaluation.report import comparison_table
    from ...guidance.trajectory_study import (TrajectoryConfig, guided_margin, quality_follows_coverage, random_spread,
                                            run_trajectory_study, share_of_draws_beaten)
    from ...io.atomic_files import atomic_write, atomic_write_json
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    require_at_least_one(args, "objects", "output_views", "random_draws")
    require_range(args, "size", VIEW_SIZE, " pixels")
    require_range(args, "input_size", VIEW_SIZE, " pixels")
    require_range(args, "mesh_resolution", MESH_RESOLUTION, " samples per side")
    if args.reconstructor == "carved-hull":
        from ...evaluation.carved_hull import CarvedHull

        if args.checkpoint:
            raise LirmUsageError("the carved hull has no weights: drop the checkpoint, or use --reconstructor lirm")
        reconstructor, description = CarvedHull(args.input_size), f"the carved visual hull ({args.input_size} px inputs)"
    else:
        source = model_with_warning(args.checkpoint)
        reconstructor, description = source.model, source.description
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    start = time.perf_counter()
    try:
        objects = synthetic_heldout(renderer, args.objects, args.size)
        config = TrajectoryConfig(mesh_resolution=args.mesh_resolution, uncertainty=not args.coverage_only,
                                  random_draws=args.random_draws, graded=not args.binary_coverage,
                                  eval=EvalConfig(output_views=args.output_views, mesh_resolution=args.mesh_resolution))
        bar = view_progress_bar((2 + args.random_draws) * len(objects), "trajectories")
        try:
            results = run_trajectory_study(reconstructor, objects, ctx, config, progress=bar_updater(bar))
        finally:
            bar.close()
    finally:
        renderer.release()
        ctx.release()
    table = comparison_table([(name, r.scores) for name, r in results.items()],
                             f"Camera trajectories, {description}, {len(objects)} objects: update 1 = the first 4 views in "
                             f"azimuth order for all; updates 2-3 chosen by each strategy (random: the mean of "
                             f"{args.random_draws} draws per object)")
    updates = len(results["guided"].coverage)
    lines = ["", "Share of the true surface seen within 60° by the inputs so far:", "",
             "| strategy | " + " | ".join(f"after update {u + 1}" for u in range(updates)) + " |", "|---|" + "---|" * updates]
    lines += [f"| {name} | " + " | ".join(f"{100 * c:.1f}%" for c in r.coverage) + " |" for name, r in results.items()]
    margins = {against: guided_margin(results, against) for against in ("random", "sequential")}
    lines += ["", "Guided minus each other strategy, object by object: the mean difference [95% interval] and the "
                  "verdict (positive = guided better; CD: the other minus guided; coverage in points):", "",
              "| against | after update | PSNR | SSIM | albedo PSNR | CD | coverage |", "|---|---|---|---|---|---|---|"]

    def cell(d, digits: int, scale: float = 1.0) -> str:
        if d is None:
            return "—"
        return f"{scale * d.mean:+.{digits}f} [{scale * d.low:+.{digits}f}, {scale * d.high:+.{digits}f}] {d.verdict}"

    for against, rows in margins.items():
        for m in rows[1:]:  # update 1 is the same views for all
            i = m["intervals"]
            lines.append(f"| {against} | {m['update']} | {cell(i['psnr'], 2)} | {cell(i['ssim'], 3)} | {cell(i['albedo'], 2)} | "
                         f"{cell(i['chamfer'], 4)} | {cell(i['coverage'], 1, 100)} |")
    spread = random_spread(results["random"])
    beaten = share_of_draws_beaten(results["guided"], results["random"])
    follows = quality_follows_coverage(results["random"])
    if args.random_draws > 1:
        lines += ["", "One random draw alone: PSNR standard deviation across draws, mean over objects, after update "
                  + ", ".join(f"{u + 1}: {v:.3f} dB" for u, v in enumerate(spread) if v is not None and u > 0) + "."]
        lines += ["Does quality follow the views? Across random draws, within objects, the correlation of PSNR with the "
                  "true-surface coverage of the views drawn, after update "
                  + ", ".join(f"{u + 1}: {v:+.2f}" for u, v in enumerate(follows) if v is not None and u > 0)
                  + " (about 0 would mean that the reconstructor's quality hardly depends on which views it gets, so "
                    "that no choice of views can beat another beyond noise; positive, that views seeing more score better)."]
    lines += ["Guided's PSNR is above " + ", ".join(f"{100 * v:.0f}% (update {u + 1})" for u, v in enumerate(beaten)
                                                  if v is not None and u > 0) + " of the random draws."]
    table += "\n".join(lines) + f"\n\n{time.perf_counter() - start:.0f} s in all.\n"
    print(table)
    if args.out:
        def margin_json(rows):
            return [{"update": m["update"], **{k: (None if d is None else d.to_dict()) for k, d in m["intervals"].items()}}
                    for m in rows]

        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), {
            "reconstructor": description, "random_draws": args.random_draws,
            "margin": {against: margin_json(rows) for against, rows in margins.items()},
            "random_psnr_spread": spread, "guided_above_random_draws": beaten, "random_psnr_coverage_correlation": follows,
            **{name: {**r.scores.to_dict(), "coverage": r.coverage, "per_object": r.per_object, "per_draw": r.per_draw}
               for name, r in results.items()}})
    return 0
