"""`lirm demo`: the main job on built-in data, headless."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("demo", help="run the main job on built-in data: render, photograph and capture a built-in object")
    parser.add_argument("-o", "--out", type=Path, default=Path("demo_output"), help="output folder (default: ./demo_output)")
    parser.add_argument("--capture-only", action="store_true", help="stop once the capture is made (no reconstruction or export)")
    parser.add_argument("--refine-minutes", type=float, metavar="M",
                        help="per-scene refinement before the export, in minutes (default: the demo's 3; fewer gives a "
                             "quicker, rougher asset; 0 exports the feed-forward LIRM state as is)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..demo import DemoConfig, run_demo

    config = replace(DemoConfig(), capture_only=args.capture_only)
    if args.refine_minutes is not None:
        if not args.refine_minutes >= 0:
            raise LirmUsageError(f"--refine-minutes must be 0 or more, got {args.refine_minutes:g}")
        config = replace(config, refine_minutes=args.refine_minutes or None)

    def say(message: str) -> None:
        progress_events.emit(message, 0, 0)
        print(message, file=sys.stderr)

    result = run_demo(args.out, config, progress=say)
    print(f"demo output is in {result.out_dir.resolve()}/")
    print(f"  overview of every built-in object under every built-in environment: {result.overview}")
    print(f"  synthetic photos: {result.photos}/ (true cameras and masks in {result.out_dir / 'truth'}/)")
    print(f"  capture made from them: {result.capture}/ (capture.json, transforms.json, masks/, prepared/)")
    a = result.accuracy
    print(f"  posed {a.get('registered', '?')} photos", end="")
    if "rotation_deg_median" in a:
        print(f"; after a similarity alignment to the truth: rotation error median {a['rotation_deg_median']:.3f} deg, "
              f"max {a['rotation_deg_max']:.3f} deg; camera-centre error median {100 * a['center_error_median']:.2f}%, "
              f"max {100 * a['center_error_max']:.2f}% of the scene size", end="")
    print()
    if "mask_iou_mean" in a:
        print(f"  automatic masks against the truth: IoU mean {a['mask_iou_mean']:.3f}, worst {a['mask_iou_min']:.3f}")
    if args.capture_only:
        return 0
    print(f"  reconstruction: {result.capture / 'reconstruction'}/ (weights: {result.weights})")
    print(f"  exported asset: {result.asset}")
    if result.relit:
        print(f"  relit: {result.relit} (rows, top to bottom: {'; '.join(result.relit_rows)})")
    test = result.relit_test
    if test is not None and test.scores:
        each = ", ".join(f"{name} {s['relight_psnr_l']:.2f}" for name, s in test.scores.items())
        print(f"  relit against the original from {test.views} new views (the relighting test, PSNR-L after a per-channel "
              f"scale): {test.mean('relight_psnr_l'):.2f} dB ({each}); placed by the camera centres, silhouette IoU "
              f"{test.alignment_iou:.3f}; details: `lirm bench relight {result.out_dir} --picture F.png`")
    if not result.trained:
        print("WARNING: no trained weights ship yet: the reconstruction and asset come from UNTRAINED weights and "
              "do not look like the mug", file=sys.stderr)
    return 0
