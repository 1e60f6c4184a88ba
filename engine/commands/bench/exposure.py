"""`lirm bench exposure`: the photos' exposures and white balances read from their backgrounds, against
a demo shoot altered with known exposures and tints."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("exposure", help="exposures and white balances read from the photos' backgrounds, "
                                                    "against the demo shoot's photos altered with known ones")
    parser.add_argument("demo_out", type=Path, help="a `lirm demo` output folder (its photos/)")
    parser.add_argument("--apart", type=float, default=1.0, help="every other photo this many stops darker (default 1)")
    parser.add_argument("--tint", type=float, default=0.15,
                        help="each photo's red up and blue down by a seeded tint within +- this many stops (default 0.15)")
    parser.add_argument("--seed", type=int, default=0)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.exposure_bench import ExposureBenchConfig, run_exposure_bench

    config = ExposureBenchConfig(apart_stops=args.apart, tint_stops=args.tint, seed=args.seed)
    print(run_exposure_bench(args.demo_out, config).report())
    return 0
