"""`lirm bench app-refine`: the steps a refinement reaches in the app against alone."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common import require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("app-refine", help="a refinement's steps in the app (a real window: $DISPLAY or a private Xvfb) against alone, on copies of a capture")
    parser.add_argument("capture", type=Path, help="a capture (only read: the runs use copies of it)")
    parser.add_argument("--seconds", type=float, default=30.0, help="the refinement's time budget (default 30)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.app_refine_bench import measure_app_refine

    require_capture(args.capture)
    print(measure_app_refine(args.capture, args.seconds).report())
    return 0
