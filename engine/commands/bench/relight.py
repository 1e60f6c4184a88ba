"""`lirm bench relight`: the demo shoot's exported asset relit beside the original object."""

from __future__ import annotations

import argparse
from pathlib import Path

from ...errors import LirmUserError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("relight", help="the demo shoot's exported asset relit beside the original object "
                                                   "under environments that lit none of the photos (the relighting test)")
    parser.add_argument("demo_out", type=Path, help="a `lirm demo` output folder (its capture/, truth/ and asset.glb)")
    parser.add_argument("--asset", type=Path, help="the export to score (default: DEMO_OUT/asset.glb)")
    parser.add_argument("--env", action="append", dest="environments",
                        help="a built-in environment or an .hdr/.exr file to relight under; repeat for more "
                             "(default: the two the demo relights under, studio and overcast)")
    parser.add_argument("--views", type=int, default=8, help="views per environment, on two rings (default 8)")
    parser.add_argument("--size", type=int, default=192, help="pixels per side of each view (default 192)")
    parser.add_argument("--picture", type=Path, help="also write the truth above the relit asset on 4 views, as a PNG")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.demo_relight_bench import run_demo_relight_bench

    if not (args.demo_out / "capture" / "capture.json").is_file() or not (args.demo_out / "truth" / "transforms.json").is_file():
        raise LirmUserError(f"{args.demo_out}: not a `lirm demo` output (it needs capture/ and truth/); run `lirm demo -o {args.demo_out}` first")
    if args.views < 2 or args.size < 32:
        raise LirmUserError(f"--views {args.views} --size {args.size}: need at least 2 views of at least 32 pixels")
    environments = tuple(args.environments) if args.environments else None
    print(run_demo_relight_bench(args.demo_out, args.asset, environments, args.views, args.size, args.picture).report())
    return 0
