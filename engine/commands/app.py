"""`lirm app`: the desktop app."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import LirmUserError
from .common import parse_size


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("app", help="the desktop app: capture, progressive reconstruction, relighting, guidance and export in one window")
    parser.add_argument("capture", type=Path, nargs="?", help="a capture folder to open (default: the last capture "
                        "opened; an empty project the first time, or with --new)")
    parser.add_argument("--demo", action="store_true", help="open the built-in demo capture (made once in the background)")
    parser.add_argument("--new", action="store_true", help="start with an empty project instead of reopening the last capture")
    parser.add_argument("--size", type=parse_size, default=(1280, 800), help="window size WxH (default 1280x800)")
    parser.add_argument("--checkpoint", type=Path, help="model weights (default: the shipped checkpoint)")
    parser.add_argument("--hdri", action="append", default=[], help="an .hdr/.exr offered in the Lighting panel; repeatable")
    parser.add_argument("--script", type=Path, help="a JSON list of steps to run in the window (tests, recorded sessions)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import os

    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise LirmUserError("no display: `lirm app` needs a desktop session (or run it under xvfb-run); "
                            "`lirm demo` runs the whole flow without a window")
    from lirm.app.window import AppConfig, run_app

    config = AppConfig(capture=args.capture, demo=args.demo, width=args.size[0], height=args.size[1], checkpoint=args.checkpoint,
                       script=args.script, extra_environments=tuple(args.hdri), reopen_last=not args.new)
    run_app(config)
    return 0
