"""`lirm bench app-idle`: the share of a CPU core the app uses while it sits idle."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..common import require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("app-idle", help="CPU the app uses while idle (a real window: $DISPLAY or a private Xvfb); goal under 3%% of a core")
    parser.add_argument("capture", type=Path, nargs="?", help="a capture to open (default: an empty project)")
    parser.add_argument("--settle", type=float, default=20.0, help="seconds to let it start before measuring (default 20)")
    parser.add_argument("--seconds", type=float, default=30.0, help="seconds measured (default 30)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.app_idle_bench import measure_idle

    if args.capture is not None:
        require_capture(args.capture)
    print(measure_idle(args.capture, args.settle, args.seconds).report())
    return 0
