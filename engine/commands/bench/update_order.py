"""`lirm bench update-order`: update sets in walk-around order against spread over the object."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common import (VIEW_SIZE, bar_updater, heldout_objects, model_with_warning, require_at_least_one, require_range,
                      view_progress_bar)


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("update-order", help="update sets in walk-around order or spread over the object: LIRM and the carved hull after updates 1-3")
    parser.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    parser.add_argument("--objects", type=int, default=8, help="held-out synthetic objects (default 8)")
    parser.add_argument("--size", type=int, default=64, help="side of the protocol views (default 64)")
    parser.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    parser.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.update_order_bench import run_update_order_bench, update_order_table
    from ...evaluation.evaluate import EvalConfig
    from ...io.atomic_files import atomic_write, atomic_write_json

    require_at_least_one(args, "objects", "output_views")
    require_range(args, "size", VIEW_SIZE, " pixels")
    source = model_with_warning(args.checkpoint)
    args.set, args.updates = "synthetic", 3
    objects = heldout_objects(args)
    bar = view_progress_bar(4, "update orders")
    try:
        result = run_update_order_bench(source.model, objects, EvalConfig(updates=3, output_views=args.output_views,
                                                                          mesh_resolution=64), progress=bar_updater(bar))
    finally:
        bar.close()
    table = update_order_table(result, [o.name for o in objects])
    print(table)
    if args.out:
        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), result)
    return 0
