"""`lirm train`: one stage of training on synthetic scenes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import LirmUsageError
from ..progress_lines import progress_bar
from .common import require_at_least_one


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("train", help="train LIRM on synthetic scenes: one stage of the coarse-to-fine schedule (torchrun for many GPUs)")
    parser.add_argument("--preset", default="tiny", choices=["tiny", "small", "paper"], help="model and schedule size (default tiny)")
    parser.add_argument("--stage", type=int, default=1, choices=[1, 2, 3], help="stage of the supplementary's schedule (default 1)")
    parser.add_argument("--max-steps", type=int, help="stop after this step (the schedules still span the whole stage)")
    parser.add_argument("--stage-steps", type=int, help="shorten the stage to this many steps (schedules compressed)")
    parser.add_argument("--resume", type=Path, help="checkpoint to continue (same stage: exactly) or to start this stage from")
    parser.add_argument("--out", type=Path, default=Path("runs/lirm"), help="run folder: metrics.csv, eval.csv, tensorboard/, checkpoints")
    parser.add_argument("--models", type=Path, help="also train on the glTF/glb models under this folder")
    parser.add_argument("--environments", type=Path, help="also light scenes with the .hdr/.exr files under this folder")
    parser.add_argument("--no-builtin-objects", action="store_true", help="only the --models folder's objects")
    parser.add_argument("--scene-views", type=int, help="views rendered per training scene (default the generator's 32); "
                        "fewer make data faster where it bounds the step, and must hold every update set's inputs")
    parser.add_argument("--scene-pool", type=int, default=0, help="draw scenes from this many seeds (0: a new scene every time)")
    parser.add_argument("--cache", type=Path, help="keep rendered scenes in this folder (useful with --scene-pool)")
    parser.add_argument("--data-seed", type=int, default=0, help="seed of the scenes and of every random choice of the data")
    parser.add_argument("--checkpoint-every", type=int, default=100, help="steps between checkpoints (default 100)")
    parser.add_argument("--eval-every", type=int, default=0, help="steps between held-out evaluations (default 0: none)")
    parser.add_argument("--eval-objects", type=int, default=2, help="held-out objects in those evaluations (default 2)")
    parser.add_argument("--workers", type=int, default=0, help="data-loader processes rendering scenes (default 0: in the training process)")
    parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu or cuda")
    parser.add_argument("--batch-scenes", type=int, help="scenes per step over all processes (default: the stage's)")
    parser.add_argument("--slim-copy", type=Path, help="at the end, also write the weights as float16 with the step but no "
                        "AdamW moments (a third of the size), with the second moments in 8 bits beside it (F.adam-v.safetensors); "
                        "--resume from it continues the step with those, or with fresh moments and a warm-up when they are missing")
    parser.add_argument("--slim-only", action="store_true", help="save only the --slim-copy (every --checkpoint-every steps "
                        "and at the end), no full checkpoints with AdamW moments: for a machine whose disk is lost after the run")
    parser.add_argument("--checkpointing", default="auto", choices=["auto", "on", "off"],
                        help="gradient checkpointing of the transformer and of the crops' renders (default auto: on GPUs); "
                        "off is faster where the memory allows (a `small` step of 16 scenes: 115 GiB)")
    parser.add_argument("--no-lpips", action="store_true", help="use the SSIM + gradient loss even when LPIPS could run")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import os

    from ..model.config import preset as model_preset
    from ..train.trainer import TrainConfig, describe, run_training, scene_config_for

    require_at_least_one(args, "max_steps", "stage_steps", "checkpoint_every")
    rank0 = os.environ.get("RANK", "0") == "0"
    scenes = _scene_config(args, scene_config_for(model_preset(args.preset).image_size), rank0)
    if args.scene_views is not None:  # the trainer checks the count against the stage's update sets
        from dataclasses import replace

        scenes = replace(scenes, views=args.scene_views)
    config = TrainConfig(preset=args.preset, stage=args.stage, out_dir=str(args.out), max_steps=args.max_steps,
                         stage_steps=args.stage_steps, resume=str(args.resume) if args.resume else None,
                         data_seed=args.data_seed, scene_pool=args.scene_pool,
                         cache_dir=str(args.cache) if args.cache else None, scenes=scenes, lpips=not args.no_lpips,
                         checkpoint_every=args.checkpoint_every, eval_every=args.eval_every,
                         eval_objects=args.eval_objects, workers=args.workers, device=args.device,
                         batch_scenes=args.batch_scenes, slim_copy=str(args.slim_copy) if args.slim_copy else None,
                         checkpointing=args.checkpointing, full_checkpoints=not args.slim_only)
    stage = config.stage_settings()
    if rank0:
        print(f"stage {args.stage} of '{args.preset}': {stage.steps} steps, lr {stage.learning_rate[0]:g} -> {stage.learning_rate[1]:g}, "
              f"{stage.batch_scenes} scenes/step, {stage.update_sets} update sets, {stage.samples_per_ray} samples/ray, "
              f"{stage.crop}px crops of {stage.target_resolution}px targets, 1/beta {stage.inv_beta[0]:g} -> {stage.inv_beta[1]:g}",
              file=sys.stderr)
    bar = progress_bar(f"stage {args.stage}", min(stage.steps, args.max_steps or stage.steps), unit="step",
                       disable=None if rank0 else True)

    def progress(record: dict) -> None:
        bar.n = record["step"]
        bar.set_postfix(loss=f"{record['loss']:.4f}", refresh=False)
        bar.refresh()

    try:
        result = run_training(config, progress=progress)
    finally:
        bar.close()
    if rank0:
        print(describe(result))
        if result.stopped_early:
            print(f"stopped at step {result.last_step}; continue with --resume {result.checkpoint}", file=sys.stderr)
    return 0


def _scene_config(args: argparse.Namespace, base, rank0: bool):
    """`base` with the built-in objects and environments plus the user's folders (each file checked,
    bad ones reported)."""
    from dataclasses import replace

    from ..synth.asset_folders import scan_environment_folder, scan_model_folder
    from ..synth.procedural_objects import BUILTIN_OBJECTS
    from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS

    objects = () if args.no_builtin_objects else tuple(BUILTIN_OBJECTS)
    environments = tuple(PROCEDURAL_ENVIRONMENTS)
    if args.models:
        scan = scan_model_folder(args.models)
        if rank0:
            print(scan.report("glTF models"), file=sys.stderr)
        objects += tuple(str(p) for p in scan.usable)
    elif args.no_builtin_objects:
        raise LirmUsageError("--no-builtin-objects needs --models FOLDER: there would be nothing to train on")
    if args.environments:
        scan = scan_environment_folder(args.environments)
        if rank0:
            print(scan.report("environments"), file=sys.stderr)
        environments += tuple(str(p) for p in scan.usable)
    return replace(base, objects=objects, environments=environments)
