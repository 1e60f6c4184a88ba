"""`lirm curve`: the training curve across GPU slices, as the README's and the model card's table."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import require_range


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("curve", help="one training curve across the GPU slices' logs: a Markdown table per block of steps and a picture")
    parser.add_argument("logs", type=Path, nargs="?", default=Path("resources/checkpoints/training-logs/small"),
                        help="the folder of slice folders (default resources/checkpoints/training-logs/small)")
    parser.add_argument("--block", type=int, default=200, help="steps per table row (default 200)")
    parser.add_argument("--png", type=Path, help="also draw the whole curve (loss and its terms per step) here")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..train.slice_curve import curve_blocks, markdown_curve, read_slices, write_curve_picture

    require_range(args, "block", (1, 100000))
    metrics, evals = read_slices(args.logs)
    print(markdown_curve(curve_blocks(metrics, evals, args.block)), end="")
    if args.png:
        title = f"{args.logs.name}: steps {metrics[0]['step']}-{metrics[-1]['step']}"
        print(f"wrote {write_curve_picture(metrics, args.png, title)}")
    return 0
