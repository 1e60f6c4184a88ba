"""`lirm train-materials`: the image-space material prior (model/material_net.py), trained on the CPU."""

from __future__ import annotations

import argparse
import json
import signal
import sys
from dataclasses import replace
from pathlib import Path

from .common import add_gltf_set_arguments, require_range


def default_out() -> Path:
    """The installed package's own checkpoint, which `lirm refine --material-network` reads."""
    from ..model.pretrained import checkpoints_folder
    from ..refine.image_materials import SHIPPED_NAME

    return checkpoints_folder() / SHIPPED_NAME


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser(
        "train-materials", help="train the image-space material prior that the refinement's materials lean on (CPU, ~55 min)")
    parser.add_argument("--out", type=Path, help="where the weights go (default: the package's resources/checkpoints/"
                        "material-net.safetensors, the one `lirm refine --material-network` reads)")
    parser.add_argument("--scenes", type=int, default=500, help="the LIRM prior's training scenes to render, 8 views each (default 500)")
    parser.add_argument("--varied-scenes", type=int, default=0,
                        help="scenes of varied materials and shapes (blobs, tori, objects with no metal or all metal) to render "
                             "after them, 8 views each (default 0: measured, not worth it yet; README)")
    parser.add_argument("--steps", type=int, default=3000, help="optimiser steps of 12 views (default 3000: the shipped weights; 1500 scored less on the held-out objects, MATERIAL_NET.md)")
    parser.add_argument("--preset", choices=("default", "small"), default="default", help="network size")
    parser.add_argument("--data", type=Path, help="keep the rendered views in this .npz and reuse it when it exists")
    parser.add_argument("--history", type=Path, help="also write the loss per step here (JSON)")
    parser.add_argument("--eval-objects", type=int, default=8,
                        help="score the trained network on this many held-out synthetic objects' input views (default 8; 0: none)")
    parser.add_argument("--eval-set", choices=("synthetic", "gltf"), default="synthetic",
                        help="score on the held-out synthetic objects or on the glTF set's models (default synthetic)")
    add_gltf_set_arguments(parser)
    parser.add_argument("--eval-only", type=Path, metavar="WEIGHTS", help="instead: only score these weights")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from ..model.material_net import PRESETS, save_material_net
    from ..train.material_net_training import (MIN_STEPS, MaterialData, MaterialTrainingConfig, render_material_data,
                                               train_material_net)

    require_range(args, "scenes", (0, 100000))
    require_range(args, "varied_scenes", (0, 100000))
    require_range(args, "eval_objects", (0, 1000))
    if args.eval_only is not None:
        from ..model.material_net import load_material_net

        net, _ = load_material_net(args.eval_only)
        _print_scores(net, args, max(args.eval_objects, 1))
        return 0
    require_range(args, "steps", (MIN_STEPS, 1000000))
    args.out = args.out if args.out is not None else default_out()
    if args.out.suffix != ".safetensors":
        from ..errors import LirmUsageError

        raise LirmUsageError(f"--out {args.out}: the file name must end in .safetensors")
    if args.scenes + args.varied_scenes == 0:
        from ..errors import LirmUsageError

        raise LirmUsageError("--scenes 0 --varied-scenes 0: nothing to train on; render at least one scene")
    config = replace(MaterialTrainingConfig(), scenes=args.scenes, varied_scenes=args.varied_scenes, steps=args.steps)
    if args.data is not None and args.data.is_file():
        print(f"reading the rendered views from {args.data}", flush=True)
        data = MaterialData.load(args.data)
    else:
        def rendered(done: int, total: int) -> None:
            if done % 25 == 0 or done == total:
                print(f"rendered {done}/{total} scenes", flush=True)

        data = render_material_data(config, rendered)
        if args.data is not None:
            data.save(args.data)
    stop = {"asked": False}

    def interrupted(*_):  # Ctrl-C ends the training at the next step and keeps what it learned
        stop["asked"] = True

    previous = signal.signal(signal.SIGINT, interrupted)

    def trained(step: int, record: dict) -> None:
        if step % 50 == 0 or step == config.steps:
            print(f"step {step}/{config.steps}: loss {record['loss']:.4f} (metallic {record['metallic']:.4f}, roughness "
                  f"{record['roughness']:.4f}, albedo {record['albedo']:.4f}), {record['seconds']:.0f} s", flush=True)

    try:
        net, history = train_material_net(data, config, PRESETS[args.preset], trained, lambda: stop["asked"])
    finally:
        signal.signal(signal.SIGINT, previous)
    if not history:
        print("stopped before the first step: nothing saved", file=sys.stderr)
        return 1
    metadata = {"training": config.to_dict(), "preset": args.preset, "steps_done": len(history),
                "final_loss": history[-1]["loss"], "seconds": history[-1]["seconds"], "views": int(len(data.masks))}
    save_material_net(net, args.out, metadata)
    if args.history:
        args.history.write_text(json.dumps(history))
    print(f"wrote {args.out} ({len(history)} steps{', stopped early' if stop['asked'] else ''})")
    if args.eval_objects:
        _print_scores(net, args, args.eval_objects)
    return 0


def _print_scores(net, args: argparse.Namespace, count: int) -> None:
    from ..evaluation.heldout_sets import gltf_heldout, synthetic_heldout
    from ..synth.asset_folders import scan_environment_folder, scan_model_folder
    from ..train.material_net_training import heldout_material_scores
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    if args.eval_set == "gltf":  # read (and refused, naming the folder) before the renderer starts
        models, environments = scan_model_folder(args.models), scan_environment_folder(args.environments)
    context = create_headless_context()
    renderer = PBRRenderer(context)
    try:
        if args.eval_set == "gltf":
            objects = gltf_heldout(renderer, models.usable, environments.usable, 128, surface_points=100)
        else:
            objects = synthetic_heldout(renderer, count, 128, surface_points=100)
    finally:
        renderer.release()
        context.release()
    rows = heldout_material_scores(net, objects)
    keys = ("metallic_psnr", "metallic_psnr_none", "roughness_psnr", "albedo_psnr")
    where = "the glTF set's models'" if args.eval_set == "gltf" else "the held-out synthetic objects'"
    print(f"\nthe network on {where} 16 input views (PSNR, dB; 'none': metallic 0 everywhere):")
    print("| object | metallic | metallic (none) | roughness | albedo |\n|---|---|---|---|---|")
    for row in rows + [{"object": "mean", **{k: float(sum(r[k] for r in rows) / len(rows)) for k in keys}}]:
        print(f"| {row['object']} | " + " | ".join(f"{row[k]:.2f}" for k in keys) + " |")
