"""`lirm bench train`: one training step's seconds, peak memory and what bounds it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("train", help="one training step of a preset and stage: seconds, peak memory, gradient checkpointing on/off, a profile")
    parser.add_argument("--preset", default="small", choices=["tiny", "small", "paper"], help="model preset (default small)")
    parser.add_argument("--stage", type=int, default=1, choices=[1, 2, 3], help="training stage (default 1)")
    parser.add_argument("--batch-scenes", type=int, help="scenes per step (default: the stage's)")
    parser.add_argument("--samples-per-ray", type=int, help="samples per ray (default: the stage's)")
    parser.add_argument("--steps", type=int, default=3, help="timed steps (default 3, after one warm-up step)")
    parser.add_argument("--warmup-steps", type=int, default=1, help="untimed steps first (default 1)")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"], help="where to run (default cpu)")
    parser.add_argument("--checkpointing", default="auto", choices=["auto", "on", "off", "both"],
                        help="gradient checkpointing of the transformer and of the crops' renders (default auto: on GPUs, as training)")
    parser.add_argument("--scene-views", type=int, help="views rendered per scene (default: the fewest the stage needs)")
    parser.add_argument("--profile", action="store_true", help="one more step under torch.profiler: the costliest operators and parts")
    parser.add_argument("--no-lpips", action="store_true", help="the SSIM + gradient perceptual loss even where LPIPS can run (as lirm train --no-lpips)")
    parser.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ...bench.train_step_bench import TrainBenchConfig, run_train_bench

    config = TrainBenchConfig(preset=args.preset, stage=args.stage, batch_scenes=args.batch_scenes, samples_per_ray=args.samples_per_ray,
                              steps=args.steps, warmup_steps=args.warmup_steps, device=args.device, checkpointing=args.checkpointing,
                              scene_views=args.scene_views, profile=args.profile, json_path=args.json,
                              lpips=not args.no_lpips)
    result = run_train_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        print(f"figures written to {args.json}")
    return 0
