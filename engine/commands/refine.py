"""`lirm refine`: per-scene refinement of a capture's field."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError, LirmUserError
from ..progress_lines import progress_bar
from ..refine.config import MATERIAL_NETWORK_USES
from .common import check_output, check_render_memory, check_render_options, require_at_least_one, require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("refine", help="per-scene refinement: fit the field to all the capture's views (one more step of its history)")
    parser.add_argument("capture", type=Path, help="a capture folder made by `lirm capture`")
    parser.add_argument("--init", choices=["auto", "lirm", "hull", "hull-lirm", "scratch"], default="auto",
                        help="start from: auto (default: the last refinement, else the latest LIRM update or the hull with its "
                             "materials, whichever agrees better with the photos, else the hull), "
                             "lirm (the latest update), hull (the masks' carved visual hull), hull-lirm (the hull's "
                             "shape with the latest update's materials) or scratch")
    parser.add_argument("--preset", choices=["fast", "default", "quality"], default="default",
                        help="settings: fast (1 min), default (3 min), quality (10 min, finer planes)")
    parser.add_argument("--minutes", type=float, help="time budget of the fit (default: the preset's)")
    parser.add_argument("--iterations", type=int, help="stop after this many steps (default: only the time budget)")
    parser.add_argument("--holdout-every", type=int, metavar="K", help="keep every K-th view out of the fit and report PSNR/SSIM on them")
    parser.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    parser.add_argument("--device", default="auto", help="auto (CUDA when present), cpu or cuda")
    parser.add_argument("--novel-views", type=int, default=4, help="orbit views rendered after the refinement (default 4)")
    parser.add_argument("--render-size", type=int, default=128, help="side of those renders in pixels (default 128)")
    parser.add_argument("--grid-resolution", type=int, default=128, help="occupancy grid voxels per side for those renders (default 128)")
    parser.add_argument("--live", type=Path, help="keep the field as it fits in this file (replaced every --live-every seconds, removed at the end)")
    parser.add_argument("--live-every", type=float, default=5.0, help="seconds between those snapshots (default 5)")
    parser.add_argument("--materials", action="store_true",
                        help="inverse-render the materials: shade them under the capture's lighting (fitted with them, "
                             "from the estimate `lirm capture` made) and fit that to the photos, so that albedo holds no "
                             "baked shading (experimental: see the README's relighting figures)")
    parser.add_argument("--no-carve-openings", dest="carve_openings", action="store_false",
                        help="leave the masks' hull as the masks make it: by default it is carved first where the "
                             "photos see through it (a cup's opening, which every mask covers; textured insides only), "
                             "and an opening whose bottom no photo saw continues down to a floor over the base "
                             "(README, 'What the photos see through the hull', 'The hollow that holds')")
    parser.add_argument("--material-network", choices=MATERIAL_NETWORK_USES, default="auto",
                        help="with --materials: hold the metallic and the albedo's colour to what the image-space material "
                             "network (resources/checkpoints/material-net.safetensors) sees in each photo. It finds metal the "
                             "photos alone cannot on objects like its training's (vases, mugs, toy blocks, bottles) and false "
                             "metal on others: 'auto' (default) only when its metal holds still as the photos are mirrored and "
                             "their exposure moved, 'on' always, 'off' never (README, 'Does the network know these photos?')")
    parser.add_argument("--light-lobes", type=int, default=None, metavar="K",
                        help="with --materials: fit K compact lights (spherical Gaussians) beside the lighting panorama, for a "
                             "sun or lamp the photos did not see (default 1; 0: the panorama alone; README: what one was worth)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from ..capture.capture_folder import Capture
    from ..export.capture_export import reconstruction_model
    from dataclasses import replace

    from ..reconstruction.refine_step import run_refine
    from ..reconstruction.session import ReconstructConfig
    from ..refine.config import refine_preset

    require_at_least_one(args, "novel_views", "holdout_every", "iterations")
    check_render_options(args)
    if not args.live_every > 0:
        raise LirmUsageError(f"--live-every must be positive, got {args.live_every}")
    if args.minutes is not None and not args.minutes > 0:
        raise LirmUsageError(f"--minutes must be positive, got {args.minutes}")
    if args.light_lobes is not None and not args.materials:
        raise LirmUsageError("--light-lobes shapes the lighting fitted with the materials; add --materials")
    if args.light_lobes is not None and not 0 <= args.light_lobes <= 8:
        raise LirmUsageError(f"--light-lobes must lie in 0..8, got {args.light_lobes}")
    require_capture(args.capture)
    check_output(args.capture, "the capture folder", folder=True)
    if args.live is not None:
        check_output(args.live, "the live field (--live)", example="live.safetensors")
    check_render_memory(args)
    device = ("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise LirmUserError("--device cuda: no CUDA device is available here; use --device cpu")
    overrides = {"device": device, "inverse_rendering": bool(args.materials)}
    if args.light_lobes is not None:
        overrides["light_lobes"] = args.light_lobes
    if args.minutes is not None:
        overrides["minutes"] = args.minutes
    if args.iterations is not None:
        overrides["iterations"] = args.iterations
        if args.minutes is None:
            overrides["minutes"] = None  # --iterations alone: run them all
    config = refine_preset(args.preset, **overrides)
    if not args.carve_openings:
        # The hull as the masks make it, and without the term that keeps the carved space empty (the two
        # were measured together: README, "The hollow that holds").
        config = replace(config, photo_carving=False, losses=replace(config.losses, outside_bounds=0.0))
    if args.material_network == "on" and not args.materials:
        raise LirmUsageError("--material-network on holds the materials the inverse rendering fits; add --materials")
    config = replace(config, material_network=args.material_network)
    source = reconstruction_model(Capture.open(args.capture), args.checkpoint)
    budget = f"{config.minutes:g} min" if config.minutes else f"{config.iterations} steps"
    print(f"refining {args.capture} on {device} for {budget} (Ctrl-C stops and keeps the best state so far)", file=sys.stderr)
    bar = progress_bar("refine", 1000, unit="‰", bar_format="{desc}: {percentage:3.0f}%|{bar}| {postfix}")

    def progress(tick) -> None:
        progress_events.emit(f"refining: step {tick.step}, loss {tick.loss:.4f}, ETA {tick.eta:.0f} s", int(1000 * tick.fraction), 1000)
        bar.n = int(1000 * tick.fraction)
        bar.set_postfix_str(f"step {tick.step}, loss {tick.loss:.4f}, batch PSNR {tick.psnr:.1f} dB, planes {tick.resolution}², "
                            f"ETA {tick.eta:.0f} s", refresh=False)
        bar.refresh()

    try:
        render = replace(ReconstructConfig(), novel_views=args.novel_views, render_size=args.render_size,
                         occupancy=replace(ReconstructConfig().occupancy, resolution=args.grid_resolution))
        result = run_refine(args.capture, source, config, init=args.init, holdout_every=args.holdout_every, render=render,
                            progress=progress, live_path=args.live, live_every=args.live_every)
    finally:
        bar.close()
    for note in result.notes:
        print(f"note: {note}")
    how = {"budget": "time budget reached", "iterations": "all iterations done", "cancelled": "cancelled: kept the best state so far"}
    print(f"refinement {result.number} (from {result.started_from}): {result.steps} steps in {result.seconds:.0f} s, "
          f"{how[result.stopped]} -> {result.out_dir}/")
    if result.holdout:
        h = result.holdout
        print(f"held-out views ({', '.join(h['views'])}): PSNR {h['psnr']:.2f} dB, SSIM {h['ssim']:.3f}")
    print(f"export it with `lirm export {args.capture}`; step back with `lirm export --update N`")
    return 0
