"""`lirm bench capture`: capture speed per stage and peak memory."""

from __future__ import annotations

import argparse
import sys
from dataclasses import asdict
from pathlib import Path

from ...errors import LirmUsageError, LirmUserError
from ..common import MAX_SIDE, require_range


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("capture", help="capture pipeline speed and peak memory for N photos")
    parser.add_argument("photos", type=Path, help="a folder of photos (the issue's figures use ../shared/data/real_instantngp_fox/images)")
    parser.add_argument("--counts", default="20,60", help="photo counts, comma separated (default 20,60)")
    parser.add_argument("--max-side", type=int, default=960, help="long side of the working images (default 960)")
    parser.add_argument("--masks", default="auto", help="mask mode, as for lirm capture")
    parser.add_argument("--json", type=Path, help="also write the results as JSON here")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.capture_bench import CaptureBenchConfig, run_capture_bench

    require_range(args, "max_side", MAX_SIDE, " pixels")
    if not args.photos.is_dir():
        raise LirmUserError(f"{args.photos}: not a folder of photos")
    try:
        counts = tuple(int(s) for s in args.counts.split(","))
    except ValueError:
        raise LirmUsageError(f"--counts must be comma-separated integers, got {args.counts!r}") from None
    config = CaptureBenchConfig(args.photos, counts, args.max_side, args.masks)
    result = run_capture_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        from ...io.atomic_files import atomic_write_json

        atomic_write_json(args.json, asdict(result))
    return 0
