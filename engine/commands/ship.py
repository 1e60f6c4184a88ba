"""`lirm ship`: a training checkpoint as shippable weights with a model card."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("ship", help="a training checkpoint as shippable fp16 weights with a model card made from the run's files")
    parser.add_argument("checkpoint", type=Path, help="the training checkpoint to ship")
    parser.add_argument("--runs", type=Path, nargs="+", required=True, help="the lirm train output folders, one per stage")
    parser.add_argument("--eval", type=Path, action="append", default=[], help="a lirm eval table (.md) for the card; repeatable")
    parser.add_argument("--notes", type=Path, help="Markdown appended to the card: limitations, what was looked at")
    parser.add_argument("--note", default="", help="one sentence stored in the weights and shown to users whenever they are used")
    parser.add_argument("--hardware", help="what the run trained on, for runs whose stageN_run.json does not record it")
    parser.add_argument("-o", "--out", type=Path, required=True, help="the weights to write, e.g. resources/checkpoints/lirm-tiny.safetensors")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..train.ship import ship

    weights, card = ship(args.checkpoint, args.out, args.runs, args.eval, args.notes, args.note, args.hardware)
    print(f"wrote {weights} ({weights.stat().st_size / 2**20:.2f} MB) and {card}")
    return 0
