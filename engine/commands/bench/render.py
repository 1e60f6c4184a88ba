"""`lirm bench render`: renderer speed."""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

from ...errors import LirmUsageError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("render", help="renderer speed: environment preprocessing and G-buffer frames per second")
    parser.add_argument("--model", default="vase", help="model file or built-in object (the issue's figures use DamagedHelmet)")
    parser.add_argument("--env", default="studio", help="built-in environment or .hdr/.exr (the issue's figures use a 1k HDR)")
    parser.add_argument("--sizes", default="512,1024", help="square image sizes, comma separated")
    parser.add_argument("--frames", type=int, default=20, help="frames per size")
    parser.add_argument("--ibl", default="default", choices=["default", "preview", "high"], help="environment filtering preset")
    parser.add_argument("--json", type=Path, help="also write the results as JSON here")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.render_bench import RenderBenchConfig, run_render_bench

    try:
        sizes = tuple(int(s) for s in args.sizes.split(","))
    except ValueError:
        raise LirmUsageError(f"--sizes must be comma-separated integers, got {args.sizes!r}") from None
    config = RenderBenchConfig(model=args.model, environment=args.env, sizes=sizes, frames=args.frames, ibl_preset=args.ibl)
    result = run_render_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        from ...io.atomic_files import atomic_write_json

        atomic_write_json(args.json, asdict(result))
    return 0
