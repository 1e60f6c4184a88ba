"""`lirm bench lighting`: the capture lighting estimate against the demo shoot's truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from ...errors import LirmUserError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("lighting", help="the capture lighting estimated from the demo shoot's photos against the environment that lit them")
    parser.add_argument("demo_out", type=Path, help="a `lirm demo` output folder (its capture/ and truth/)")
    parser.add_argument("--env", help="the true environment (default: the one truth/transforms.json names)")
    parser.add_argument("--refined", action="store_true",
                        help="the lighting the latest refinement fitted with the materials, instead of the backgrounds' estimate")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.lighting_bench import run_lighting_bench

    if not (args.demo_out / "capture" / "capture.json").is_file() or not (args.demo_out / "truth" / "transforms.json").is_file():
        raise LirmUserError(f"{args.demo_out}: not a `lirm demo` output (it needs capture/ and truth/); run `lirm demo -o {args.demo_out}` first")
    print(run_lighting_bench(args.demo_out, args.env, args.refined).report())
    return 0
