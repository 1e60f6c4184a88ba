"""`lirm bench synth`: synthetic training views per second and a contact sheet."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..common import require_at_least_one, require_range


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("synth", help="synthetic training views per second, and a contact sheet of them")
    parser.add_argument("--scenes", type=int, default=4, help="scenes to generate (default 4)")
    parser.add_argument("--views", type=int, default=8, help="views per scene (default 8; training uses 32)")
    parser.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    parser.add_argument("--sheet", type=Path, help="write a contact sheet PNG here (image, background, albedo, roughness, metallic, normal per view)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ...bench.synth_bench import SynthBenchConfig, run_synth_bench

    require_at_least_one(args, "scenes", "views")
    require_range(args, "size", (16, 2048), " pixels")
    base = SynthBenchConfig()
    config = replace(base, scenes=args.scenes, scene=replace(base.scene, views=args.views, size=args.size), sheet_path=args.sheet)
    result = run_synth_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if result.sheet:
        print(f"contact sheet: {result.sheet}")
    return 0
