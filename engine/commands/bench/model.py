"""`lirm bench model`: the update loop's seconds, memory, tokens and FLOPs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ...errors import LirmUsageError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("model", help="LIRM update loop: seconds, peak memory, tokens and FLOPs per update, and the all-views-at-once baseline")
    parser.add_argument("--preset", default="small", choices=["tiny", "small", "paper"], help="model preset (default small)")
    parser.add_argument("--updates", type=int, default=8, help="timed progressive updates (default 8)")
    parser.add_argument("--views-per-update", type=int, default=4, help="views per update (default 4)")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"], help="where to run (default cpu)")
    parser.add_argument("--image-size", type=int, help="input views of this size instead of the preset's (e.g. 256 for paper)")
    parser.add_argument("--no-baseline", action="store_true", help="skip the all-views-at-once baseline")
    parser.add_argument("--baseline-max-views", type=int, help="skip baseline sizes above this many views")
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.model_bench import ModelBenchConfig, run_model_bench

    if args.updates < 1 or args.views_per_update < 1:
        raise LirmUsageError("--updates and --views-per-update must be at least 1")
    config = ModelBenchConfig(preset=args.preset, updates=args.updates, views_per_update=args.views_per_update, device=args.device,
                              baseline=not args.no_baseline, image_size=args.image_size, baseline_max_views=args.baseline_max_views, json_path=args.json)
    result = run_model_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        print(f"figures written to {args.json}")
    return 0
