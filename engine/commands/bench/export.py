"""`lirm bench export`: export speed, or the round trip of a PBR model through export."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common import check_export_memory, check_export_options


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("export", help="export speed: marching cubes, decimation, unwrap, bake and write of a 20k-face asset")
    parser.add_argument("--grid", type=int, default=256, help="marching-cubes grid (default 256)")
    parser.add_argument("--faces", type=int, default=20_000, help="face budget (default 20000)")
    parser.add_argument("--texture", type=int, default=1024, help="texture side (default 1024)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    parser.add_argument("--model", type=Path, help="instead: round trip of this PBR model (as a field) through export, rendered against the original")
    parser.add_argument("--env", default="studio", help="environment of that comparison (default studio)")
    parser.add_argument("--sheet", type=Path, help="picture of the comparison: original (top) and exported (bottom) per view")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import json

    from ...bench.export_bench import ExportBenchConfig, RoundTripConfig, run_asset_round_trip, run_export_bench

    check_export_options(args)
    check_export_memory(args)
    if args.model:
        figures = run_asset_round_trip(RoundTripConfig(args.model, args.env, grid=args.grid, faces=args.faces,
                                                       texture=args.texture, sheet=args.sheet))
    else:
        figures = run_export_bench(ExportBenchConfig(args.grid, args.faces, args.texture))
    print(json.dumps(figures, indent=2))
    if args.json:
        from ...io.atomic_files import atomic_write_json

        atomic_write_json(args.json, figures)
    return 0
