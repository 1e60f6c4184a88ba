"""`lirm bench suggest`: seconds to compute next-view suggestions."""

from __future__ import annotations

import argparse
from pathlib import Path

from ...errors import LirmUsageError
from ..common import require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("suggest", help="seconds to compute next-view suggestions for a capture (target < 1 s)")
    parser.add_argument("capture", type=Path, help="a capture folder (with or without a reconstruction)")
    parser.add_argument("--k", type=int, default=4, help="suggestions (default 4)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs; the median is reported (default 3)")
    parser.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    parser.add_argument("--json", type=Path, help="also write the figures here")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import statistics
    import time

    from ...guidance.suggest import suggest_for_capture
    from lirm.renderer.context import create_headless_context

    require_capture(args.capture)
    if args.repeats < 1 or args.k < 1:
        raise LirmUsageError("--repeats and --k must be at least 1")
    start = time.perf_counter()
    ctx = create_headless_context()
    context_seconds = time.perf_counter() - start
    runs = []
    try:
        for _ in range(args.repeats):
            timings: dict[str, float] = {}
            start = time.perf_counter()
            result = suggest_for_capture(ctx, args.capture, args.k, args.checkpoint, timings=timings)
            timings["total"] = time.perf_counter() - start
            runs.append(timings)
    finally:
        ctx.release()
    median = {name: statistics.median(r.get(name, 0.0) for r in runs) for name in runs[0]}
    parts = ", ".join(f"{name} {median[name]:.3f}" for name in runs[0] if name != "total")
    print(f"suggest ({result.surface}, {len(result.vertices)} vertices, {len(result.suggestions)} of k={args.k}): "
          f"median of {args.repeats}: {median['total']:.3f} s ({parts}); GL context {context_seconds:.2f} s once")
    if args.json:
        from ...io.atomic_files import atomic_write_json

        atomic_write_json(args.json, {"capture": str(args.capture), "surface": result.surface, "runs": runs,
                                      "median": median, "context_seconds": context_seconds})
    return 0
