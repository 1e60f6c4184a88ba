"""`lirm reconstruct`: progressive LIRM updates on a prepared capture."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError
from ..progress_lines import progress_bar
from .common import check_output, check_render_memory, check_render_options, require_at_least_one, require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("reconstruct", help="run progressive LIRM updates on a prepared capture; pictures after each update")
    parser.add_argument("capture", type=Path, help="a capture folder made by `lirm capture`")
    parser.add_argument("--checkpoint", type=Path, help="model weights (.safetensors); default: the shipped checkpoint, else UNTRAINED weights")
    parser.add_argument("--preset", choices=["tiny", "small", "paper"],
                        help="model size when no checkpoint is given (default: the shipped checkpoint's, see resources/checkpoints/MODEL_CARD.md)")
    parser.add_argument("--views-per-update", type=int, default=4, help="views fed to each update (default 4)")
    parser.add_argument("--updates", type=int, help="stop after this many updates (default: until the views run out)")
    parser.add_argument("--novel-views", type=int, default=4, help="orbit views rendered after each update (default 4)")
    parser.add_argument("--render-size", type=int, default=128, help="side of those renders in pixels (default 128)")
    parser.add_argument("--grid-resolution", type=int, default=128, help="occupancy grid voxels per side for those renders (default 128; the paper uses 250)")
    parser.add_argument("--frames", help="instead of all updates: ONE more update with these frames (comma-separated ids), on top of the latest")
    parser.add_argument("--after", type=int, help="with --frames: on top of this update instead (0 = afresh); later updates are set aside, not deleted")
    parser.add_argument("--order", choices=["spread", "frames"], default="spread",
                        help="which views go into which update: spread (default: each set farthest-first over the object) or frames (frame order)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..model.pretrained import load_model
    from ..reconstruction.session import ReconstructConfig, run_reconstruction

    require_at_least_one(args, "views_per_update", "novel_views", "updates")
    check_render_options(args)
    if args.after is not None and not args.frames:
        raise LirmUsageError("--after goes with --frames (the views of the one update to run)")
    require_capture(args.capture)
    check_output(args.capture, "the capture folder", folder=True)
    check_render_memory(args)
    source = load_model(args.checkpoint, args.preset)
    if source.warning:
        print("\n" + "!" * 100 + f"\n{source.warning}\n" + "!" * 100 + "\n", file=sys.stderr)
    config = replace(ReconstructConfig(), views_per_update=args.views_per_update, updates=args.updates, order=args.order,
                     novel_views=args.novel_views, render_size=args.render_size,
                     occupancy=replace(ReconstructConfig().occupancy, resolution=args.grid_resolution))
    bar = progress_bar("LIRM updates", unit="update")

    def progress(stage: str, done: int, total: int) -> None:
        progress_events.emit(stage, done, total)
        bar.total = total
        bar.n = done
        bar.refresh()

    try:
        if args.frames:
            from ..reconstruction.session import run_next_update

            frames = [f.strip() for f in args.frames.split(",") if f.strip()]
            progress("update", 0, 1)
            result = run_next_update(args.capture, source, frames, args.after, config)
            progress("update", 1, 1)
        else:
            result = run_reconstruction(args.capture, source, config, progress=progress)
    finally:
        bar.close()
    print(f"weights: {source.description}" + ("" if source.trained else "  (UNTRAINED)"))
    if source.note:
        print(f"about these weights: {source.note}")
    for r in result.updates:
        print(f"update {r.update}: {len(r.frames)} views ({', '.join(r.frames)}) in {r.seconds:.2f} s; "
              f"renders in {r.render_seconds:.1f} s ({100 * r.skipped_samples:.0f}% of samples skipped) -> {args.capture / r.out_dir}/")
    print(f"summary: {result.out_dir / 'summary.json'}")
    if source.warning:
        print(source.warning, file=sys.stderr)
    return 0
