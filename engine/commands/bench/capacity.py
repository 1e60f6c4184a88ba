"""`lirm bench capacity`: the paper's single-object capacity test."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ...errors import LirmUsageError


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("capacity", help="overfit the model on one rendered object (the paper's capacity test): input-view PSNR and albedo PSNR")
    parser.add_argument("--preset", default="tiny", choices=["tiny", "small", "paper"], help="model preset (default tiny)")
    parser.add_argument("--object", default="vase", help="built-in object (vase, mug, toy_block, bottle) or a .glb/.gltf")
    parser.add_argument("--steps", type=int, default=1500, help="training steps (default 1500)")
    parser.add_argument("--json", type=Path, help="also write the figures and the loss history to this JSON file")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ...io.atomic_files import atomic_write_json
    from ...io.images import to_uint8, write_png
    from ...synth.object_views import ObjectViewsConfig
    from ...train.overfit import OverfitConfig, comparison_sheet, render_training_views, run_overfit

    if args.steps < 1:
        raise LirmUsageError("--steps must be at least 1")
    config = replace(OverfitConfig(), preset=args.preset, steps=args.steps, views=ObjectViewsConfig(object_name=args.object),
                     eval_every=max(args.steps // 6, 1))

    def progress(record: dict) -> None:
        if "psnr" in record:
            print(f"step {record['step']}: loss {record['loss']:.5f}, input-view PSNR {record['psnr']:.2f} dB, "
                  f"albedo PSNR {record['albedo_psnr']:.2f} dB", file=sys.stderr)

    views = render_training_views(config)
    result = run_overfit(config, views, progress=progress)
    print(f"capacity ({config.preset} preset, '{args.object}', {len(config.azimuths_deg)} views of {config.views.size}px, {len(result.history)} steps): "
          f"input-view PSNR {result.psnr:.2f} dB (per view {', '.join(f'{p:.2f}' for p in result.psnr_per_view)}), "
          f"albedo PSNR {result.albedo_psnr:.2f} dB; {result.seconds:.0f} s of training, {result.seconds_per_step:.2f} s per step")
    if args.json:
        atomic_write_json(args.json, result.to_dict())
        sheet = write_png(args.json.with_suffix(".png"), to_uint8(comparison_sheet(views, result)))
        print(f"figures written to {args.json}; renders against the truth (rows: image, render, albedo, rendered albedo) in {sheet}")
    return 0
