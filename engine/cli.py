"""The `lirm` command line. Each subcommand maps onto a dataclass config; only built features appear."""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import asdict
from pathlib import Path

from lirm.renderer.context import GLContextError

from . import progress_events
from .errors import LirmResourceError, LirmUsageError, LirmUserError
from .progress_lines import progress_bar

# Exit codes (README "Exit codes"): what went wrong, for scripts and for the app's background jobs.
EXIT_OK = 0  # done
EXIT_NOTHING_USABLE = 1  # the run finished but produced nothing usable (e.g. no photo could be posed)
EXIT_USAGE = 2  # bad usage: an unknown or missing argument, an option value out of its range
EXIT_INPUT = 3  # bad input: a file, folder, capture or checkpoint that cannot be used, or a missing prerequisite
EXIT_RESOURCES = 4  # not enough memory or disk for what was asked
EXIT_INTERNAL = 70  # an internal error: a bug (sysexits.h EX_SOFTWARE)
EXIT_CANCELLED = 130  # cancelled with Ctrl-C (128 + SIGINT)

# Accepted ranges of the options that size the work (checked before any work starts).
CAPTURE_SIZE = (32, 2048)  # lirm capture --size
MAX_SIDE = (64, 16384)  # lirm capture --max-side
RENDER_SIZE = (8, 4096)  # reconstruct/refine --render-size
GRID_RESOLUTION = (16, 1024)  # reconstruct/refine --grid-resolution
EXPORT_GRID = (16, 1024)  # export --grid, bench export --grid
TEXTURE = (64, 4096)  # export --texture
VIEW_SIZE = (16, 1024)  # eval and bench --size (protocol views)
MESH_RESOLUTION = (16, 1024)  # eval and bench --mesh-resolution

# The options to lower when a command runs out of memory all the same.
MEMORY_OPTIONS = {
    "capture": ("--max-side", "--size"), "reconstruct": ("--render-size", "--grid-resolution", "--views-per-update"),
    "refine": ("--render-size", "--grid-resolution", "--preset"), "export": ("--grid", "--texture"),
    "render": ("--size", "--supersample"), "eval": ("--size", "--objects", "--mesh-resolution"),
    "train": ("--preset", "--workers"), "bench model": ("--preset", "--views-per-update"), "bench capacity": ("--preset",),
    "bench export": ("--grid", "--texture"), "bench trajectory": ("--size", "--mesh-resolution"),
    "bench refine": ("--size", "--objects"), "bench update-order": ("--size",), "bench synth": ("--size", "--views"),
    "bench render": ("--sizes",), "bench capture": ("--max-side", "--counts"),
}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)  # bad usage: argparse prints it and exits with EXIT_USAGE (2)
    _configure_logging(args.verbose)
    for stream in (sys.stdout, sys.stderr):  # a log file sees each line when it is printed, not at exit
        if hasattr(stream, "reconfigure") and not stream.isatty():
            try:
                stream.reconfigure(line_buffering=True)
            except (ValueError, OSError):
                pass
    try:
        return args.run(args)
    except LirmUsageError as err:
        print(f"error: {err} (see `lirm {args.command} --help`)", file=sys.stderr)
        return EXIT_USAGE
    except LirmResourceError as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_RESOURCES
    except (LirmUserError, GLContextError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:
        print("cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except Exception as err:  # noqa: BLE001 - the last line of defence: a sentence, never a bare traceback
        if _out_of_memory(err):
            print(f"error: {_out_of_memory_sentence(args, err)}", file=sys.stderr)
            return EXIT_RESOURCES
        import traceback

        crash = _write_crash_report(sys.argv[1:] if argv is None else argv)
        if args.verbose or crash is None:
            traceback.print_exc()
        where = f"the traceback written to {crash}" if crash else "the traceback above"
        print(f"error: internal error: {type(err).__name__}: {err}; this is a bug in LIRM Studio: please report it "
              f"with {where}", file=sys.stderr)
        return EXIT_INTERNAL


def _out_of_memory(err: BaseException) -> bool:
    """A MemoryError, or torch's (CPU or CUDA) allocation failure, which is a RuntimeError."""
    if isinstance(err, MemoryError):
        return True
    text = str(err).lower()
    return isinstance(err, RuntimeError) and ("out of memory" in text or "can't allocate memory" in text)


def _out_of_memory_sentence(args: argparse.Namespace, err: BaseException) -> str:
    from .resources import available_memory_bytes, format_bytes

    options = [o for o in MEMORY_OPTIONS.get(args.command, ()) if hasattr(args, o.lstrip("-").replace("-", "_"))]
    now = [f"{o} (now {getattr(args, o.lstrip('-').replace('-', '_'))})" for o in options]
    free = available_memory_bytes()
    lower = (f"lower {', '.join(now[:-1])} or {now[-1]}" if len(now) > 1 else f"lower {now[0]}") if now else \
        "run it on a machine with more memory"
    return (f"not enough memory: `lirm {args.command}` ran out of memory ({type(err).__name__})"
            + (f" with {format_bytes(free)} free now" if free is not None else "")
            + f"; {lower}, or close other programs, and run it again")


def _write_crash_report(argv: list[str]) -> Path | None:
    """The traceback of the exception being handled, in CACHE/lirm/crash-<time>.txt (CACHE: $XDG_CACHE_HOME,
    else ~/.cache; the system's temporary folder when neither can be written); None when nothing can."""
    import os
    import platform
    import tempfile
    import time
    import traceback

    try:
        from importlib.metadata import version

        lirm_version = version("lirm")
    except Exception:  # noqa: BLE001 - not installed as a distribution
        lirm_version = "unknown"
    text = (f"lirm {lirm_version}, Python {platform.python_version()} on {platform.platform()}\n"
            f"command: lirm {' '.join(argv)}\ntime: {time.strftime('%Y-%m-%d %H:%M:%S')}\n\n{traceback.format_exc()}")
    cache = os.environ.get("XDG_CACHE_HOME")
    cache = Path(cache) if cache and Path(cache).is_absolute() else Path.home() / ".cache"
    stamp = f"crash-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}"
    for folder in (cache / "lirm", Path(tempfile.gettempdir()) / "lirm"):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            for n in range(100):  # never overwrite an earlier report
                path = folder / (stamp + (f"-{n}" if n else "") + ".txt")
                try:
                    with open(path, "x", encoding="utf-8") as f:
                        f.write(text)
                    return path
                except FileExistsError:
                    continue
        except OSError:
            continue
    return None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lirm", description="LIRM Studio: photos of an object to a relightable 3D asset.")
    parser.add_argument("-v", "--verbose", action="store_true", help="more logging")
    parser.add_argument("--version", action="version", version=f"lirm (LIRM Studio) {_version()}")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)

    ap = sub.add_parser("app", help="the desktop app: capture, progressive reconstruction, relighting, guidance and export in one window")
    ap.add_argument("capture", type=Path, nargs="?", help="a capture folder to open (default: the last capture "
                    "opened; an empty project the first time, or with --new)")
    ap.add_argument("--demo", action="store_true", help="open the built-in demo capture (made once in the background)")
    ap.add_argument("--new", action="store_true", help="start with an empty project instead of reopening the last capture")
    ap.add_argument("--size", type=_size, default=(1280, 800), help="window size WxH (default 1280x800)")
    ap.add_argument("--checkpoint", type=Path, help="model weights (default: the shipped checkpoint)")
    ap.add_argument("--hdri", action="append", default=[], help="an .hdr/.exr offered in the Lighting panel; repeatable")
    ap.add_argument("--script", type=Path, help="a JSON list of steps to run in the window (tests, recorded sessions)")
    ap.set_defaults(run=_run_app)

    demo = sub.add_parser("demo", help="run the main job on built-in data: render, photograph and capture a built-in object")
    demo.add_argument("-o", "--out", type=Path, default=Path("demo_output"), help="output folder (default: ./demo_output)")
    demo.add_argument("--capture-only", action="store_true", help="stop once the capture is made (no reconstruction or export)")
    demo.set_defaults(run=_run_demo)

    render = sub.add_parser("render", help="render an asset from an orbit of cameras: beauty + G-buffer PNGs + transforms.json")
    render.add_argument("asset", nargs="?", help="a .gltf/.glb/.obj file or a built-in object name (see --list)")
    render.add_argument("--env", default="studio", help="built-in environment (studio, sky, overcast), an .hdr/.exr path, or a capture folder (the lighting its photos were taken in)")
    render.add_argument("--views", type=int, default=8, help="number of orbit views (default 8)")
    render.add_argument("--size", type=_size, default=(512, 512), help="image size WxH (default 512x512)")
    render.add_argument("-o", "--out", type=Path, help="output folder (required)")
    render.add_argument("--elevation", type=float, default=20.0, help="camera elevation in degrees (default 20)")
    render.add_argument("--fov", type=float, default=40.0, help="field of view of the shorter image side, degrees (default 40)")
    render.add_argument("--exposure", type=float, default=0.0, help="camera exposure in EV (default 0)")
    render.add_argument("--env-rotation", type=float, default=0.0, help="environment rotation about +Z in degrees")
    render.add_argument("--supersample", type=int, default=2, choices=[1, 2, 3, 4], help="anti-aliasing factor (default 2)")
    render.add_argument("--no-background", action="store_true", help="transparent background (RGBA beauty)")
    render.add_argument("--keep-scale", action="store_true", help="do not fit the asset into the unit sphere")
    render.add_argument("--cameras", type=Path, metavar="TRANSFORMS_JSON",
                        help="render from exactly these cameras (a transforms.json, e.g. one this command wrote) with the "
                             "asset in its own frame (not refitted), so that an original and its reconstruction compare "
                             "view for view; --views, --size, --elevation and --fov are then unused")
    render.add_argument("--ibl", default="default", choices=["default", "preview", "high"],
                        help="environment filtering quality: preview is faster on a CPU, high is finer on a GPU")
    render.add_argument("--list", action="store_true", help="list the built-in objects and environments and exit")
    render.set_defaults(run=_run_render)

    cap = sub.add_parser("capture", help="photos, a video or a camera -> a posed, masked, cropped capture folder")
    cap.add_argument("inputs", help="a folder of photos, a video file, or camera:N for live camera N; with --add, the photos to add")
    cap.add_argument("capture", nargs="?", type=Path, help="with --add: the capture folder to extend")
    cap.add_argument("-o", "--out", type=Path, help="the capture folder to create")
    cap.add_argument("--add", action="store_true", help="add the photos in INPUTS to the existing capture CAPTURE")
    cap.add_argument("--resume", action="store_true", help="INPUTS is an interrupted capture folder: finish its remaining stages")
    cap.add_argument("--reference-originals", action="store_true",
                     help="refer to the original photos where they are instead of copying them into the capture")
    cap.add_argument("--fix-mask", metavar="FRAME_ID", help="INPUTS is a corrected mask (PNG, 255 = object) for this frame of "
                     "CAPTURE; the correction propagates to the other views")
    cap.add_argument("--real-size", metavar="height=M|width=M", help="INPUTS is a capture: the object's real height (or "
                     "largest width), e.g. height=0.095 or height=9.5cm; every export is then in metres")
    cap.add_argument("--check", action="store_true", help="INPUTS is a capture: check its files against capture.json, "
                     "make again what can be (crops, masks) and name what cannot")
    cap.add_argument("--undo-fix-mask", action="store_true", help="INPUTS is a capture: put back the masks the last --fix-mask replaced")
    cap.add_argument("--poses", help="use known poses: a transforms.json (NeRF, instant-ngp, nerfstudio) or a COLMAP model folder")
    cap.add_argument("--masks", default="auto", help="auto (alpha if every photo has one, else automatic), alpha, automatic, or a folder of masks")
    cap.add_argument("--max-side", type=int, default=1280, help="long side of the working images (default 1280)")
    cap.add_argument("--size", type=int, default=256, help="side of the network's square crops (default 256)")
    cap.add_argument("--reference", type=Path, help="report pose errors against this transforms.json (for known test scenes)")
    cap.set_defaults(run=_run_capture)

    rec = sub.add_parser("reconstruct", help="run progressive LIRM updates on a prepared capture; pictures after each update")
    rec.add_argument("capture", type=Path, help="a capture folder made by `lirm capture`")
    rec.add_argument("--checkpoint", type=Path, help="model weights (.safetensors); default: the shipped checkpoint, else UNTRAINED weights")
    rec.add_argument("--preset", choices=["tiny", "small", "paper"],
                     help="model size when no checkpoint is given (default: the shipped checkpoint's, see resources/checkpoints/MODEL_CARD.md)")
    rec.add_argument("--views-per-update", type=int, default=4, help="views fed to each update (default 4)")
    rec.add_argument("--updates", type=int, help="stop after this many updates (default: until the views run out)")
    rec.add_argument("--novel-views", type=int, default=4, help="orbit views rendered after each update (default 4)")
    rec.add_argument("--render-size", type=int, default=128, help="side of those renders in pixels (default 128)")
    rec.add_argument("--grid-resolution", type=int, default=128, help="occupancy grid voxels per side for those renders (default 128; the paper uses 250)")
    rec.add_argument("--frames", help="instead of all updates: ONE more update with these frames (comma-separated ids), on top of the latest")
    rec.add_argument("--after", type=int, help="with --frames: on top of this update instead (0 = afresh); later updates are set aside, not deleted")
    rec.add_argument("--order", choices=["spread", "frames"], default="spread",
                     help="which views go into which update: spread (default: each set farthest-first over the object) or frames (frame order)")
    rec.set_defaults(run=_run_reconstruct)

    rf = sub.add_parser("refine", help="per-scene refinement: fit the field to all the capture's views (one more step of its history)")
    rf.add_argument("capture", type=Path, help="a capture folder made by `lirm capture`")
    rf.add_argument("--init", choices=["auto", "lirm", "hull", "scratch"], default="auto",
                    help="start from: auto (default: the last refinement, else the latest LIRM update, else the hull), "
                         "lirm (the latest update), hull (the masks' carved visual hull) or scratch")
    rf.add_argument("--preset", choices=["fast", "default", "quality"], default="default",
                    help="settings: fast (1 min), default (3 min), quality (10 min, finer planes)")
    rf.add_argument("--minutes", type=float, help="time budget of the fit (default: the preset's)")
    rf.add_argument("--iterations", type=int, help="stop after this many steps (default: only the time budget)")
    rf.add_argument("--holdout-every", type=int, metavar="K", help="keep every K-th view out of the fit and report PSNR/SSIM on them")
    rf.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    rf.add_argument("--device", default="auto", help="auto (CUDA when present), cpu or cuda")
    rf.add_argument("--novel-views", type=int, default=4, help="orbit views rendered after the refinement (default 4)")
    rf.add_argument("--render-size", type=int, default=128, help="side of those renders in pixels (default 128)")
    rf.add_argument("--grid-resolution", type=int, default=128, help="occupancy grid voxels per side for those renders (default 128)")
    rf.add_argument("--live", type=Path, help="keep the field as it fits in this file (replaced every --live-every seconds, removed at the end)")
    rf.add_argument("--live-every", type=float, default=5.0, help="seconds between those snapshots (default 5)")
    rf.add_argument("--materials", action="store_true",
                    help="inverse-render the materials: shade them under the capture's lighting (fitted with them, "
                         "from the estimate `lirm capture` made) and fit that to the photos, so that albedo holds no "
                         "baked shading (experimental: see the README's relighting figures)")
    rf.set_defaults(run=_run_refine)

    ex = sub.add_parser("export", help="the capture's latest reconstruction as a textured PBR .glb")
    ex.add_argument("capture", type=Path, help="a capture folder with a reconstruction (`lirm reconstruct`)")
    ex.add_argument("-o", "--out", type=Path, help="the .glb to write (default CAPTURE/export/asset.glb, as the app; "
                    "replaced only by a complete file)")
    ex.add_argument("--faces", type=int, default=20_000, help="face budget after decimation (default 20000)")
    ex.add_argument("--texture", type=int, default=1024, help="texture side in pixels, 64..4096 (default 1024)")
    ex.add_argument("--grid", type=int, default=256, help="marching-cubes grid per side (default 256)")
    ex.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    ex.add_argument("--no-normal-map", action="store_true", help="leave out the tangent-space normal map")
    ex.add_argument("--obj", action="store_true", help="also write NAME.obj + NAME.mtl + PNG textures beside the .glb")
    ex.add_argument("--update", type=int, help="export the state after this update (default: the latest)")
    ex.set_defaults(run=_run_export)

    sg = sub.add_parser("suggest", help="where to shoot next: ranked views, a sentence each, and a view-sphere heat map")
    sg.add_argument("capture", type=Path, help="a capture folder (with or without a reconstruction)")
    sg.add_argument("--k", type=int, default=4, help="how many views to suggest (default 4)")
    sg.add_argument("--can-turn", action="store_true", help="the object can be turned over: also suggest views from below "
                    "it (by default, an object standing on something is only shot from above)")
    sg.add_argument("--heat-map", type=Path, help="write the view-sphere heat map here (default CAPTURE/guidance/heat_map.png)")
    sg.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    sg.set_defaults(run=_run_suggest)

    tr = sub.add_parser("train", help="train LIRM on synthetic scenes: one stage of the coarse-to-fine schedule (torchrun for many GPUs)")
    tr.add_argument("--preset", default="tiny", choices=["tiny", "small", "paper"], help="model and schedule size (default tiny)")
    tr.add_argument("--stage", type=int, default=1, choices=[1, 2, 3], help="stage of the supplementary's schedule (default 1)")
    tr.add_argument("--max-steps", type=int, help="stop after this step (the schedules still span the whole stage)")
    tr.add_argument("--stage-steps", type=int, help="shorten the stage to this many steps (schedules compressed)")
    tr.add_argument("--resume", type=Path, help="checkpoint to continue (same stage: exactly) or to start this stage from")
    tr.add_argument("--out", type=Path, default=Path("runs/lirm"), help="run folder: metrics.csv, eval.csv, tensorboard/, checkpoints")
    tr.add_argument("--models", type=Path, help="also train on the glTF/glb models under this folder")
    tr.add_argument("--environments", type=Path, help="also light scenes with the .hdr/.exr files under this folder")
    tr.add_argument("--no-builtin-objects", action="store_true", help="only the --models folder's objects")
    tr.add_argument("--scene-pool", type=int, default=0, help="draw scenes from this many seeds (0: a new scene every time)")
    tr.add_argument("--cache", type=Path, help="keep rendered scenes in this folder (useful with --scene-pool)")
    tr.add_argument("--data-seed", type=int, default=0, help="seed of the scenes and of every random choice of the data")
    tr.add_argument("--checkpoint-every", type=int, default=100, help="steps between checkpoints (default 100)")
    tr.add_argument("--eval-every", type=int, default=0, help="steps between held-out evaluations (default 0: none)")
    tr.add_argument("--eval-objects", type=int, default=2, help="held-out objects in those evaluations (default 2)")
    tr.add_argument("--workers", type=int, default=0, help="data-loader processes rendering scenes (default 0: in the training process)")
    tr.add_argument("--device", default="auto", help="auto (CUDA when present), cpu or cuda")
    tr.add_argument("--no-lpips", action="store_true", help="use the SSIM + gradient loss even when LPIPS could run")
    tr.set_defaults(run=_run_train)

    ev = sub.add_parser("eval", help="the paper's metrics after updates 1-4 on a held-out set, as a Markdown table")
    ev.add_argument("checkpoint", type=Path, nargs="?", help="model weights (.safetensors), e.g. a training checkpoint (default: the shipped checkpoint)")
    ev.add_argument("--set", default="synthetic", help="synthetic (default), gltf, or a capture folder")
    ev.add_argument("--objects", type=int, default=4, help="objects of the synthetic set (default 4)")
    ev.add_argument("--size", type=int, default=128, help="side of the protocol views in pixels (default 128)")
    ev.add_argument("--updates", type=int, default=4, help="updates to score (default 4)")
    ev.add_argument("--output-views", type=int, help="score at most this many output views per object (default: all 12)")
    ev.add_argument("--models", type=Path, default=Path("../shared/data/pbr_models"), help="glTF folder of the gltf set")
    ev.add_argument("--environments", type=Path, default=Path("../shared/data/envmaps"), help="HDR folder of the gltf set")
    ev.add_argument("--mesh-resolution", type=int, default=96, help="marching-cubes grid for the Chamfer distance (default 96)")
    ev.add_argument("--baselines", action="store_true",
                    help="also score, on the same views, the untrained network of the same architecture, a sphere of the inputs' "
                         "mean colour and the carved visual hull coloured from the views (no learning)")
    ev.add_argument("--refine", action="store_true",
                    help="also refine after the last update on the same input views: the rows 'refined from LIRM' and "
                         "'refined from the hull', with the seconds each took")
    ev.add_argument("--refine-minutes", type=float, help="time budget of each refinement (default: lirm refine's, 3 minutes)")
    ev.add_argument("--materials", action="store_true",
                    help="the refined rows inverse-render the materials (as `lirm refine --materials`), under the lighting "
                         "estimated from the input views' backgrounds")
    ev.add_argument("--no-relight", action="store_true",
                    help="skip the relighting test (each row's .glb export rendered under an environment that lit none "
                         "of the inputs; about 10 s per object and row on 2 cores)")
    ev.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    ev.set_defaults(run=_run_eval)

    sh = sub.add_parser("ship", help="a training checkpoint as shippable fp16 weights with a model card made from the run's files")
    sh.add_argument("checkpoint", type=Path, help="the training checkpoint to ship")
    sh.add_argument("--runs", type=Path, nargs="+", required=True, help="the lirm train output folders, one per stage")
    sh.add_argument("--eval", type=Path, action="append", default=[], help="a lirm eval table (.md) for the card; repeatable")
    sh.add_argument("--notes", type=Path, help="Markdown appended to the card: limitations, what was looked at")
    sh.add_argument("--note", default="", help="one sentence stored in the weights and shown to users whenever they are used")
    sh.add_argument("--hardware", help="what the run trained on, for runs whose stageN_run.json does not record it")
    sh.add_argument("-o", "--out", type=Path, required=True, help="the weights to write, e.g. resources/checkpoints/lirm-tiny.safetensors")
    sh.set_defaults(run=_run_ship)

    bench = sub.add_parser("bench", help="benchmarks")
    bench_sub = bench.add_subparsers(title="benchmarks", metavar="BENCH", required=True)
    bm = bench_sub.add_parser("model", help="LIRM update loop: seconds, peak memory, tokens and FLOPs per update, and the all-views-at-once baseline")
    bm.add_argument("--preset", default="small", choices=["tiny", "small", "paper"], help="model preset (default small)")
    bm.add_argument("--updates", type=int, default=8, help="timed progressive updates (default 8)")
    bm.add_argument("--views-per-update", type=int, default=4, help="views per update (default 4)")
    bm.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"], help="where to run (default cpu)")
    bm.add_argument("--no-baseline", action="store_true", help="skip the all-views-at-once baseline")
    bm.add_argument("--baseline-max-views", type=int, help="skip baseline sizes above this many views")
    bm.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    bm.set_defaults(run=_run_bench_model)
    bk = bench_sub.add_parser("capacity", help="overfit the model on one rendered object (the paper's capacity test): input-view PSNR and albedo PSNR")
    bk.add_argument("--preset", default="tiny", choices=["tiny", "small", "paper"], help="model preset (default tiny)")
    bk.add_argument("--object", default="vase", help="built-in object (vase, mug, toy_block, bottle) or a .glb/.gltf")
    bk.add_argument("--steps", type=int, default=1500, help="training steps (default 1500)")
    bk.add_argument("--json", type=Path, help="also write the figures and the loss history to this JSON file")
    bk.set_defaults(run=_run_bench_capacity)
    bx = bench_sub.add_parser("export", help="export speed: marching cubes, decimation, unwrap, bake and write of a 20k-face asset")
    bx.add_argument("--grid", type=int, default=256, help="marching-cubes grid (default 256)")
    bx.add_argument("--faces", type=int, default=20_000, help="face budget (default 20000)")
    bx.add_argument("--texture", type=int, default=1024, help="texture side (default 1024)")
    bx.add_argument("--json", type=Path, help="also write the figures here")
    bx.add_argument("--model", type=Path, help="instead: round trip of this PBR model (as a field) through export, rendered against the original")
    bx.add_argument("--env", default="studio", help="environment of that comparison (default studio)")
    bx.add_argument("--sheet", type=Path, help="picture of the comparison: original (top) and exported (bottom) per view")
    bx.set_defaults(run=_run_bench_export)

    bg = bench_sub.add_parser("suggest", help="seconds to compute next-view suggestions for a capture (target < 1 s)")
    bg.add_argument("capture", type=Path, help="a capture folder (with or without a reconstruction)")
    bg.add_argument("--k", type=int, default=4, help="suggestions (default 4)")
    bg.add_argument("--repeats", type=int, default=3, help="timed runs; the median is reported (default 3)")
    bg.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    bg.add_argument("--json", type=Path, help="also write the figures here")
    bg.set_defaults(run=_run_bench_suggest)

    bt = bench_sub.add_parser("trajectory", help="next views chosen by guidance, at random or sequentially: quality after updates 2 and 3 (held-out synthetic set)")
    bt.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    bt.add_argument("--objects", type=int, default=4, help="held-out synthetic objects (default 4)")
    bt.add_argument("--size", type=int, default=64, help="side of the protocol views in pixels (default 64)")
    bt.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    bt.add_argument("--mesh-resolution", type=int, default=48, help="marching-cubes grid for guidance and the Chamfer distance (default 48)")
    bt.add_argument("--coverage-only", action="store_true", help="guided views by coverage alone, without the model's uncertainty (an ablation)")
    bt.add_argument("--binary-coverage", action="store_true",
                    help="guided views by binary coverage (seen within 60° or not) instead of viewing quality (an ablation)")
    bt.add_argument("--reconstructor", choices=("lirm", "carved-hull"), default="lirm",
                    help="what reconstructs: the LIRM model (default) or the carved visual hull coloured from the views, "
                         "a reconstructor without learning whose quality comes only from the views it gets")
    bt.add_argument("--input-size", type=int, default=64, help="the carved hull's input views in pixels (default 64, as the shipped tiny model's)")
    bt.add_argument("--random-draws", type=int, default=5, help="random choices per object; random's score is their mean (default 5)")
    bt.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    bt.set_defaults(run=_run_bench_trajectory)

    bf = bench_sub.add_parser("refine", help="refinement quality against its time budget (30 s, 1, 3, 10 min) on a held-out set, with peak memory")
    bf.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    bf.add_argument("--set", choices=("synthetic", "gltf"), default="synthetic", help="held-out set (default synthetic)")
    bf.add_argument("--objects", type=int, default=4, help="held-out synthetic objects (default 4)")
    bf.add_argument("--size", type=int, default=128, help="side of the protocol views and of the input crops (default 128)")
    bf.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    bf.add_argument("--minutes", type=float, nargs="+", default=[0.5, 1.0, 3.0, 10.0], help="budgets (default 0.5 1 3 10)")
    bf.add_argument("--init", choices=("lirm", "hull", "scratch"), default="lirm", help="start from (default lirm)")
    bf.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                    help="a refinement setting, e.g. losses.eikonal=0, edge_ray_fraction=0, plane_resolutions=(128,); repeatable")
    bf.add_argument("--models", type=Path, default=Path("../shared/data/pbr_models"), help="glTF folder of the gltf set")
    bf.add_argument("--environments", type=Path, default=Path("../shared/data/envmaps"), help="HDR folder of the gltf set")
    bf.add_argument("--warm-start", action="store_true",
                    help="instead: refining again after new views, cold (from LIRM) for the first --minutes against warm "
                         "(from the earlier refinement) for 1/4, 1/2 and all of it")
    bf.add_argument("--json", type=Path, help="also write every object's numbers here")
    bf.set_defaults(run=_run_bench_refine)

    bl = bench_sub.add_parser("lighting", help="the capture lighting estimated from the demo shoot's photos against the environment that lit them")
    bl.add_argument("demo_out", type=Path, help="a `lirm demo` output folder (its capture/ and truth/)")
    bl.add_argument("--env", help="the true environment (default: the one truth/transforms.json names)")
    bl.set_defaults(run=_run_bench_lighting)

    bu = bench_sub.add_parser("update-order", help="update sets in walk-around order or spread over the object: LIRM and the carved hull after updates 1-3")
    bu.add_argument("checkpoint", type=Path, nargs="?", help="model weights (default: the shipped checkpoint)")
    bu.add_argument("--objects", type=int, default=8, help="held-out synthetic objects (default 8)")
    bu.add_argument("--size", type=int, default=64, help="side of the protocol views (default 64)")
    bu.add_argument("--output-views", type=int, default=6, help="output views scored per object (default 6 of 12)")
    bu.add_argument("-o", "--out", type=Path, help="also write the table (.md) and the numbers (.json beside it)")
    bu.set_defaults(run=_run_bench_update_order)

    bs = bench_sub.add_parser("synth", help="synthetic training views per second, and a contact sheet of them")
    bs.add_argument("--scenes", type=int, default=4, help="scenes to generate (default 4)")
    bs.add_argument("--views", type=int, default=8, help="views per scene (default 8; training uses 32)")
    bs.add_argument("--size", type=int, default=256, help="image side in pixels (default 256)")
    bs.add_argument("--sheet", type=Path, help="write a contact sheet PNG here (image, background, albedo, roughness, metallic, normal per view)")
    bs.set_defaults(run=_run_bench_synth)
    br = bench_sub.add_parser("render", help="renderer speed: environment preprocessing and G-buffer frames per second")
    br.add_argument("--model", default="vase", help="model file or built-in object (the issue's figures use DamagedHelmet)")
    br.add_argument("--env", default="studio", help="built-in environment or .hdr/.exr (the issue's figures use a 1k HDR)")
    br.add_argument("--sizes", default="512,1024", help="square image sizes, comma separated")
    br.add_argument("--frames", type=int, default=20, help="frames per size")
    br.add_argument("--ibl", default="default", choices=["default", "preview", "high"], help="environment filtering preset")
    br.add_argument("--json", type=Path, help="also write the results as JSON here")
    br.set_defaults(run=_run_bench_render)
    bc = bench_sub.add_parser("capture", help="capture pipeline speed and peak memory for N photos")
    bc.add_argument("photos", type=Path, help="a folder of photos (the issue's figures use ../shared/data/real_instantngp_fox/images)")
    bc.add_argument("--counts", default="20,60", help="photo counts, comma separated (default 20,60)")
    bc.add_argument("--max-side", type=int, default=960, help="long side of the working images (default 960)")
    bc.add_argument("--masks", default="auto", help="mask mode, as for lirm capture")
    bc.add_argument("--json", type=Path, help="also write the results as JSON here")
    bc.set_defaults(run=_run_bench_capture)
    for name, command in sub.choices.items():  # for messages: `lirm COMMAND --help`
        command.set_defaults(command=name)
    for name, command in bench_sub.choices.items():
        command.set_defaults(command=f"bench {name}")
    return parser


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 512x512, got {text!r}") from None
    return w, h


def _configure_logging(verbose: bool) -> None:
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    log = logging.getLogger("lirm")
    log.handlers[:] = [handler]
    log.setLevel(logging.DEBUG if verbose else logging.INFO)
    log.propagate = False


def _require_at_least_one(args: argparse.Namespace, *names: str) -> None:
    """Refuse counts below 1 (None means "not given" and passes)."""
    for name in names:
        value = getattr(args, name)
        if value is not None and value < 1:
            raise LirmUsageError(f"--{name.replace('_', '-')} must be at least 1, got {value}")


def _require_range(args: argparse.Namespace, name: str, accepted: tuple[int, int], unit: str = "") -> None:
    """Refuse an option value outside `accepted` (inclusive; None means "not given" and passes)."""
    value = getattr(args, name)
    low, high = accepted
    if value is not None and not low <= value <= high:
        raise LirmUsageError(f"--{name.replace('_', '-')} must be between {low} and {high}{unit}, got {value}")


def _check_memory(args: argparse.Namespace, needs: list[tuple[str, tuple[int, int], object]], together: bool = True) -> None:
    """Refuse (LirmResourceError) settings whose memory does not fit in the memory available now;
    `needs`: (option, accepted range, bytes as a function of its value) per memory-hungry option."""
    from .resources import MemoryNeed, check_memory

    check_memory(args.command, [MemoryNeed(option, getattr(args, option.lstrip("-").replace("-", "_")), bytes_for, accepted[0])
                                for option, accepted, bytes_for in needs], together=together)


def _check_render_options(args: argparse.Namespace) -> None:
    _require_range(args, "render_size", RENDER_SIZE, " pixels")
    _require_range(args, "grid_resolution", GRID_RESOLUTION, " voxels per side")


def _check_render_memory(args: argparse.Namespace) -> None:
    """reconstruct/refine: the occupancy grid and one picture's buffers are held together."""
    from .resources import occupancy_grid_bytes, render_bytes

    _check_memory(args, [("--render-size", RENDER_SIZE, render_bytes), ("--grid-resolution", GRID_RESOLUTION, occupancy_grid_bytes)])


def _check_export_options(args: argparse.Namespace) -> None:
    _require_range(args, "grid", EXPORT_GRID, " samples per side")
    _require_range(args, "texture", TEXTURE, " pixels")
    if args.faces < 100:
        raise LirmUsageError(f"--faces must be at least 100, got {args.faces}")


def _check_export_memory(args: argparse.Namespace) -> None:
    """export: the marching-cubes grid, then (after it is freed) the texture bake."""
    from .resources import bake_bytes, mesh_grid_bytes

    _check_memory(args, [("--grid", EXPORT_GRID, mesh_grid_bytes), ("--texture", TEXTURE, bake_bytes)], together=False)


def _check_output(path: Path, what: str, **kwargs) -> None:
    from .io.output_paths import check_writable_output

    check_writable_output(path, what, **kwargs)


def _require_capture(folder: Path) -> None:
    if not (folder / "capture.json").exists():
        photos = folder.is_dir() and any(p.suffix.lower() in (".jpg", ".jpeg", ".png") for p in folder.iterdir())
        if photos:  # a photo folder given where a capture was expected: capture it into a new folder
            target = folder.parent / f"{folder.name}_capture"
            raise LirmUserError(f"{folder} holds photos, not a capture (no capture.json); make a capture of them first "
                                f"with `lirm capture {folder} -o {target}` and use {target}")
        raise LirmUserError(f"{folder} is not a capture folder (no capture.json); make one with `lirm capture PHOTOS -o {folder}`")


def _parse_real_size(text: str) -> tuple[str, float]:
    """'height=0.095', 'width=12cm', 'height=95 mm' -> ('height', metres)."""
    import re

    match = re.fullmatch(r"\s*(height|width)\s*=\s*([0-9]*\.?[0-9]+)\s*(m|cm|mm)?\s*", text)
    if not match:
        raise LirmUsageError(f"--real-size {text!r}: write height=METRES or width=METRES (e.g. height=0.095 or height=9.5cm)")
    value = float(match.group(2)) * {"m": 1.0, "cm": 0.01, "mm": 0.001, None: 1.0}[match.group(3)]
    if not 0.001 <= value <= 100.0:
        raise LirmUsageError(f"--real-size {text!r}: {value:g} m is outside 1 mm..100 m")
    return match.group(1), value


def _exports_a_refinement(capture: Path, update: int | None) -> bool:
    """Whether the step `lirm export` takes is a refinement (fitted to the photos, not the weights' alone)."""
    from .capture.capture_folder import Capture

    updates = Capture.open(capture).updates
    if not updates:
        return False
    entry = updates[-1] if update is None or not 1 <= update <= len(updates) else updates[update - 1]
    return entry.get("kind") == "refine"


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("lirm")
    except PackageNotFoundError:
        return "unknown (not installed)"


def _model_with_warning(checkpoint):
    """The model to use (see model/pretrained.py), its untrained warning shown on stderr."""
    from .model.pretrained import load_model

    source = load_model(checkpoint)
    if source.warning:
        print(source.warning, file=sys.stderr)
    return source


def _bar_updater(bar):
    """A (message, done, total) progress callback that moves a tqdm bar and emits progress events."""
    def progress(message: str, done: int, total: int) -> None:
        progress_events.emit(message, done, total)
        bar.n = done
        bar.set_description(message)
        bar.refresh()
    return progress


def _progress_bar(total: int, desc: str):
    return progress_bar(desc, total, unit="view")


def _run_render(args: argparse.Namespace) -> int:
    from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS
    from lirm.renderer.pbr_renderer import PBRRenderer
    from lirm.renderer.context import create_headless_context

    from .assets.asset_source import resolve_asset
    from .assets.environment_files import resolve_environment
    from .orbit_render import OrbitRenderConfig, render_orbit
    from .synth.procedural_objects import BUILTIN_OBJECTS

    if args.list:
        print("built-in objects:      " + ", ".join(BUILTIN_OBJECTS))
        print("built-in environments: " + ", ".join(PROCEDURAL_ENVIRONMENTS))
        return 0
    if args.asset is None or args.out is None:
        raise LirmUsageError("lirm render needs an ASSET and -o OUT_DIR (lirm render --list shows the built-in assets)")
    try:
        config = OrbitRenderConfig(
            views=args.views, width=args.size[0], height=args.size[1], elevation_deg=args.elevation, fov_deg=args.fov,
            supersample=args.supersample, background=not args.no_background, exposure_ev=args.exposure,
            environment_rotation_deg=args.env_rotation, normalize=not args.keep_scale,
        )
    except ValueError as err:
        raise LirmUsageError(str(err)) from None
    _check_output(args.out, "the output folder (-o)", folder=True)
    model = resolve_asset(args.asset)
    environment = resolve_environment(args.env)
    cameras = None
    if args.cameras is not None:
        from .orbit_render import cameras_from_transforms

        from dataclasses import replace

        from .orbit_render import MAX_RENDER_SIDE

        cameras = cameras_from_transforms(args.cameras)
        largest = max(max(c.width, c.height) for c in cameras) * args.supersample
        if largest > MAX_RENDER_SIDE:
            raise LirmUsageError(f"{args.cameras}: its cameras render {largest} pixels a side with supersample "
                                 f"{args.supersample}, more than {MAX_RENDER_SIDE}: lower --supersample")
        config = replace(config, views=len(cameras), normalize=False)
    from lirm.renderer.ibl import IBL_PRESETS

    ctx = create_headless_context()
    renderer = PBRRenderer(ctx, IBL_PRESETS[args.ibl])
    try:
        with _progress_bar(config.views, "rendering") as bar:
            result = render_orbit(renderer, model, environment, config, args.out, progress=lambda done, total: bar.update(1),
                                  cameras=cameras)
    finally:
        renderer.release()
        ctx.release()
    print(f"wrote {len(result.cameras)} views of {model.source.name} under {environment.name} to {result.out_dir}/")
    print("  beauty/ radiance/ albedo/ roughness/ metallic/ normal/ depth/ mask/ transforms.json")
    return 0


def _run_capture(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .capture.capture_lock import capture_lock
    from .capture.pipeline import CaptureConfig, add_to_capture, run_capture
    from .capture.report import format_capture_report
    from .resources import crop_bytes

    _require_range(args, "size", CAPTURE_SIZE, " pixels")
    _require_range(args, "max_side", MAX_SIDE, " pixels")
    if args.resume or args.add:  # an existing capture (not one? _require_capture says so below)
        existing = Path(args.inputs) if args.resume else args.capture
        if existing is not None and existing.is_dir():
            _check_output(existing, "the capture folder", folder=True)
    elif not (args.fix_mask or args.check or args.undo_fix_mask) and args.out is not None:
        _check_output(args.out, "the capture folder (-o)", folder=True)
    _check_memory(args, [("--size", CAPTURE_SIZE, crop_bytes)])
    config = CaptureConfig(masks=args.masks, poses=args.poses)
    config = replace(config, ingest=replace(config.ingest, max_side=args.max_side, copy_originals=not args.reference_originals),
                     crop=replace(config.crop, size=args.size))
    source: str | int = args.inputs
    if args.inputs.startswith("camera:"):
        try:
            source = int(args.inputs.split(":", 1)[1])
        except ValueError:
            raise LirmUsageError(f"{args.inputs}: write a camera as camera:0, camera:1, ...") from None
    bars: dict = {}

    def progress(stage: str, done: int, total: int) -> None:
        progress_events.emit(stage, done, total)
        bar = bars.get(stage)
        if bar is None:
            for other in bars.values():
                other.close()
            bar = bars[stage] = progress_bar(stage, total, leave=False)
        bar.total = total
        bar.n = done
        bar.refresh()

    if args.fix_mask:
        import cv2

        from .capture.pipeline import fix_mask

        if args.capture is None:
            raise LirmUsageError("lirm capture --fix-mask FRAME_ID MASK.png CAPTURE: name the capture folder")
        mask = cv2.imread(args.inputs, cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise LirmUserError(f"{args.inputs}: cannot read the corrected mask; save it as a PNG, 255 = object")
        with capture_lock(args.capture, "lirm capture --fix-mask"):
            fixed = fix_mask(args.capture, args.fix_mask, mask, config)
        print(f"mask of {fixed.fixed} replaced; the correction changed {len(fixed.changed)} other views: "
              f"{', '.join(fixed.changed) or 'none'}")
        for frame, lost in fixed.withheld.items():
            print(f"  not applied to {frame}: it would have removed {lost:.0%} of its mask; correct that view itself "
                  f"if it is wrong")
        print(f"  the replaced masks are kept in {fixed.backup}; `lirm capture --undo-fix-mask {args.capture}` puts them back")
        return 0
    if args.real_size:
        from .capture.capture_folder import Capture

        _require_capture(Path(args.inputs))
        which, metres = _parse_real_size(args.real_size)
        with capture_lock(args.inputs, "lirm capture --real-size"):
            capture = Capture.open(args.inputs)
            capture.settings["real_size"] = {which: metres}
            capture.log("real size", **{which: metres})
            capture.save()
        print(f"{args.inputs}: the object is {metres:g} m {'tall' if which == 'height' else 'wide'}; exports are in metres from now on")
        return 0
    if args.check or args.resume:
        from .capture.capture_check import check_capture

        _require_capture(Path(args.inputs))
        with capture_lock(args.inputs, "lirm capture --check"):
            checked = check_capture(args.inputs)
        if args.check or not checked.clean:
            print("\n".join(checked.lines()))
        if args.check:
            return 0 if not checked.unrepairable else 1
    if args.undo_fix_mask:
        from .capture.mask_fix import undo_mask_fix

        with capture_lock(args.inputs, "lirm capture --undo-fix-mask"):
            restored = undo_mask_fix(args.inputs, config.crop)
        print(f"masks put back as they were before the last correction: {', '.join(restored)}")
        return 0
    try:
        if args.resume:
            from .capture.pipeline import resume_capture

            with capture_lock(args.inputs, "lirm capture --resume"):
                summary = resume_capture(Path(args.inputs), config, progress=progress)
        elif args.add:
            if args.capture is None:
                raise LirmUsageError("lirm capture --add PHOTOS CAPTURE: name the capture folder to extend")
            _require_capture(args.capture)
            with capture_lock(args.capture, "lirm capture --add"):
                summary = add_to_capture(args.capture, source, config, progress=progress)
        else:
            if args.out is None:
                raise LirmUsageError("lirm capture PHOTOS -o CAPTURE: name the capture folder to create with -o")
            summary = run_capture(source, args.out, config, progress=progress)
    finally:
        for bar in bars.values():
            bar.close()
    print(format_capture_report(summary, reference=args.reference))
    return 0 if summary.reconstructable else 1


def _run_reconstruct(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .model.pretrained import load_model
    from .reconstruction.session import ReconstructConfig, run_reconstruction

    _require_at_least_one(args, "views_per_update", "novel_views", "updates")
    _check_render_options(args)
    if args.after is not None and not args.frames:
        raise LirmUsageError("--after goes with --frames (the views of the one update to run)")
    _require_capture(args.capture)
    _check_output(args.capture, "the capture folder", folder=True)
    _check_render_memory(args)
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
            from .reconstruction.session import run_next_update

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


def _run_refine(args: argparse.Namespace) -> int:
    import torch

    from .capture.capture_folder import Capture
    from .export.capture_export import reconstruction_model
    from dataclasses import replace

    from .reconstruction.refine_step import run_refine
    from .reconstruction.session import ReconstructConfig
    from .refine.config import refine_preset

    _require_at_least_one(args, "novel_views", "holdout_every", "iterations")
    _check_render_options(args)
    if not args.live_every > 0:
        raise LirmUsageError(f"--live-every must be positive, got {args.live_every}")
    if args.minutes is not None and not args.minutes > 0:
        raise LirmUsageError(f"--minutes must be positive, got {args.minutes}")
    _require_capture(args.capture)
    _check_output(args.capture, "the capture folder", folder=True)
    if args.live is not None:
        _check_output(args.live, "the live field (--live)", example="live.safetensors")
    _check_render_memory(args)
    device = ("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise LirmUserError("--device cuda: no CUDA device is available here; use --device cpu")
    overrides = {"device": device, "inverse_rendering": bool(args.materials)}
    if args.minutes is not None:
        overrides["minutes"] = args.minutes
    if args.iterations is not None:
        overrides["iterations"] = args.iterations
        if args.minutes is None:
            overrides["minutes"] = None  # --iterations alone: run them all
    config = refine_preset(args.preset, **overrides)
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


def _export_progress(stage: str, done: int, total: int) -> None:
    progress_events.emit(stage, done, total)
    print(f"[{done}/{total}] {stage}", file=sys.stderr)


def _run_export(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .export.capture_export import export_capture
    from .export.export_asset import ExportConfig
    from .export.field_mesh import MeshExtractionConfig

    _check_export_options(args)
    _require_capture(args.capture)
    if args.out is None:
        args.out = args.capture / "export" / "asset.glb"
        args.out.parent.mkdir(parents=True, exist_ok=True)
    _check_output(args.out, "the asset (-o)", make_parents=False, example=f"{args.capture.name or 'asset'}.glb")
    if args.obj:
        _check_output(args.out.with_suffix(".obj"), "the OBJ copy (--obj)", make_parents=False)
    _check_export_memory(args)
    config = ExportConfig(mesh=replace(MeshExtractionConfig(), resolution=args.grid, face_budget=args.faces),
                          texture_size=args.texture, normal_map=not args.no_normal_map, obj=args.obj)
    result, source = export_capture(args.capture, args.out, config, args.checkpoint,
                                    progress=_export_progress, update=args.update)
    if not source.trained:
        print(f"WARNING: exported from UNTRAINED weights ({source.description}): the asset does not look like the object", file=sys.stderr)
    elif source.note and not _exports_a_refinement(args.capture, args.update):
        # The caveat about the shipped weights, as every command that uses them prints it.
        print(f"about these weights: {source.note}", file=sys.stderr)
    timings = ", ".join(f"{k} {v:.1f} s" for k, v in result.seconds.items())
    print(f"{result.path}: {result.faces} faces, {result.vertices} vertices, {result.texture_size}px textures ({timings})")
    from .capture.capture_folder import Capture

    real = Capture.open(args.capture).settings.get("real_size")
    if real:
        which, metres = next(iter(real.items()))
        print(f"in metres: the object's {which} is {metres:g} m as stated; its base is on y = 0")
    else:
        print(f"note: the scale is arbitrary (the photos' units); give the real size with "
              f"`lirm capture --real-size height=METRES {args.capture}` to export in metres")
    return 0


def _run_suggest(args: argparse.Namespace) -> int:
    from .guidance.suggest import suggest_for_capture, write_guidance, write_heat_map
    from lirm.renderer.context import create_headless_context

    _require_at_least_one(args, "k")
    _require_capture(args.capture)
    if args.heat_map is not None:
        _check_output(args.heat_map, "the heat map (--heat-map)", example="heat_map.png")
    _check_output(args.capture / "guidance", "the capture's guidance folder", folder=True)
    ctx = create_headless_context()
    try:
        result = suggest_for_capture(ctx, args.capture, args.k, args.checkpoint, can_turn=args.can_turn)
    finally:
        ctx.release()
    for note in result.notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"surface: {result.surface}; covered now {100 * result.coverage_before:.0f}%, "
          f"after these shots {100 * result.coverage_after:.0f}%")
    print("distances are in object radii (the object fits a ball of radius 1 in the capture's frame); "
          f"your photos were taken from about {result.photo_distance:.1f}")
    for n, s in enumerate(result.suggestions, start=1):
        where = "from your last photo" if n == 1 else f"then, from view {n - 1}"
        sentence = s.sentence[:1].lower() + s.sentence[1:]
        print(f"{n}. azimuth {s.azimuth_deg:.0f}°, elevation {s.elevation_deg:.0f}°, distance {s.distance:.1f} radii: "
              f"{where}, {sentence} ({_shot_worth(s.new_coverage)})")
    if not result.suggestions:
        print("the surface is covered from every reachable angle: no more views needed")
    heat_path = args.heat_map or args.capture / "guidance" / "heat_map.png"
    print(f"heat map: {write_heat_map(heat_path, result.heat_map, result.suggestions, result.candidates)}")
    files = write_guidance(args.capture / "guidance", result)
    print(f"for the app: {files['suggestions']} and {files['coverage']} (per-vertex coverage)")
    return 0


def _shot_worth(new_coverage: float) -> str:
    """What a suggested shot brings, in the photographer's terms."""
    if new_coverage >= 0.005:
        return f"+{100 * new_coverage:.0f}% of the surface newly covered"
    return "a squarer look at parts seen only at a slant so far"


def _run_bench_trajectory(args: argparse.Namespace) -> int:
    import time

    from .evaluation.evaluate import EvalConfig
    from .evaluation.heldout_sets import synthetic_heldout
    from .evaluation.report import comparison_table
    from .guidance.trajectory_study import (TrajectoryConfig, guided_margin, quality_follows_coverage, random_spread,
                                            run_trajectory_study, share_of_draws_beaten)
    from .io.atomic_files import atomic_write, atomic_write_json
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    _require_at_least_one(args, "objects", "output_views", "random_draws")
    _require_range(args, "size", VIEW_SIZE, " pixels")
    _require_range(args, "input_size", VIEW_SIZE, " pixels")
    _require_range(args, "mesh_resolution", MESH_RESOLUTION, " samples per side")
    if args.reconstructor == "carved-hull":
        from .evaluation.carved_hull import CarvedHull

        if args.checkpoint:
            raise LirmUsageError("the carved hull has no weights: drop the checkpoint, or use --reconstructor lirm")
        reconstructor, description = CarvedHull(args.input_size), f"the carved visual hull ({args.input_size} px inputs)"
    else:
        source = _model_with_warning(args.checkpoint)
        reconstructor, description = source.model, source.description
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    start = time.perf_counter()
    try:
        objects = synthetic_heldout(renderer, args.objects, args.size)
        config = TrajectoryConfig(mesh_resolution=args.mesh_resolution, uncertainty=not args.coverage_only,
                                  random_draws=args.random_draws, graded=not args.binary_coverage,
                                  eval=EvalConfig(output_views=args.output_views, mesh_resolution=args.mesh_resolution))
        bar = _progress_bar((2 + args.random_draws) * len(objects), "trajectories")
        try:
            results = run_trajectory_study(reconstructor, objects, ctx, config, progress=_bar_updater(bar))
        finally:
            bar.close()
    finally:
        renderer.release()
        ctx.release()
    table = comparison_table([(name, r.scores) for name, r in results.items()],
                             f"Camera trajectories, {description}, {len(objects)} objects: update 1 = the first 4 views in "
                             f"azimuth order for all; updates 2-3 chosen by each strategy (random: the mean of "
                             f"{args.random_draws} draws per object)")
    updates = len(results["guided"].coverage)
    lines = ["", "Share of the true surface seen within 60° by the inputs so far:", "",
             "| strategy | " + " | ".join(f"after update {u + 1}" for u in range(updates)) + " |", "|---|" + "---|" * updates]
    lines += [f"| {name} | " + " | ".join(f"{100 * c:.1f}%" for c in r.coverage) + " |" for name, r in results.items()]
    margins = {against: guided_margin(results, against) for against in ("random", "sequential")}
    lines += ["", "Guided minus each other strategy, object by object: the mean difference [95% interval] and the "
                  "verdict (positive = guided better; CD: the other minus guided; coverage in points):", "",
              "| against | after update | PSNR | SSIM | albedo PSNR | CD | coverage |", "|---|---|---|---|---|---|---|"]

    def cell(d, digits: int, scale: float = 1.0) -> str:
        if d is None:
            return "—"
        return f"{scale * d.mean:+.{digits}f} [{scale * d.low:+.{digits}f}, {scale * d.high:+.{digits}f}] {d.verdict}"

    for against, rows in margins.items():
        for m in rows[1:]:  # update 1 is the same views for all
            i = m["intervals"]
            lines.append(f"| {against} | {m['update']} | {cell(i['psnr'], 2)} | {cell(i['ssim'], 3)} | {cell(i['albedo'], 2)} | "
                         f"{cell(i['chamfer'], 4)} | {cell(i['coverage'], 1, 100)} |")
    spread = random_spread(results["random"])
    beaten = share_of_draws_beaten(results["guided"], results["random"])
    follows = quality_follows_coverage(results["random"])
    if args.random_draws > 1:
        lines += ["", "One random draw alone: PSNR standard deviation across draws, mean over objects, after update "
                  + ", ".join(f"{u + 1}: {v:.3f} dB" for u, v in enumerate(spread) if v is not None and u > 0) + "."]
        lines += ["Does quality follow the views? Across random draws, within objects, the correlation of PSNR with the "
                  "true-surface coverage of the views drawn, after update "
                  + ", ".join(f"{u + 1}: {v:+.2f}" for u, v in enumerate(follows) if v is not None and u > 0)
                  + " (about 0 would mean that the reconstructor's quality hardly depends on which views it gets, so "
                    "that no choice of views can beat another beyond noise; positive, that views seeing more score better)."]
    lines += ["Guided's PSNR is above " + ", ".join(f"{100 * v:.0f}% (update {u + 1})" for u, v in enumerate(beaten)
                                                  if v is not None and u > 0) + " of the random draws."]
    table += "\n".join(lines) + f"\n\n{time.perf_counter() - start:.0f} s in all.\n"
    print(table)
    if args.out:
        def margin_json(rows):
            return [{"update": m["update"], **{k: (None if d is None else d.to_dict()) for k, d in m["intervals"].items()}}
                    for m in rows]

        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), {
            "reconstructor": description, "random_draws": args.random_draws,
            "margin": {against: margin_json(rows) for against, rows in margins.items()},
            "random_psnr_spread": spread, "guided_above_random_draws": beaten, "random_psnr_coverage_correlation": follows,
            **{name: {**r.scores.to_dict(), "coverage": r.coverage, "per_object": r.per_object, "per_draw": r.per_draw}
               for name, r in results.items()}})
    return 0


def _run_bench_suggest(args: argparse.Namespace) -> int:
    import statistics
    import time

    from .guidance.suggest import suggest_for_capture
    from lirm.renderer.context import create_headless_context

    _require_capture(args.capture)
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
        from .io.atomic_files import atomic_write_json

        atomic_write_json(args.json, {"capture": str(args.capture), "surface": result.surface, "runs": runs,
                                      "median": median, "context_seconds": context_seconds})
    return 0


def _scene_config(args: argparse.Namespace, base, rank0: bool):
    """`base` with the built-in objects and environments plus the user's folders (each file checked,
    bad ones reported)."""
    from dataclasses import replace

    from .synth.asset_folders import scan_environment_folder, scan_model_folder
    from .synth.procedural_objects import BUILTIN_OBJECTS
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


def _run_train(args: argparse.Namespace) -> int:
    import os

    from .model.config import preset as model_preset
    from .train.trainer import TrainConfig, describe, run_training, scene_config_for

    _require_at_least_one(args, "max_steps", "stage_steps", "checkpoint_every")
    rank0 = os.environ.get("RANK", "0") == "0"
    scenes = _scene_config(args, scene_config_for(model_preset(args.preset).image_size), rank0)
    config = TrainConfig(preset=args.preset, stage=args.stage, out_dir=str(args.out), max_steps=args.max_steps,
                         stage_steps=args.stage_steps, resume=str(args.resume) if args.resume else None,
                         data_seed=args.data_seed, scene_pool=args.scene_pool,
                         cache_dir=str(args.cache) if args.cache else None, scenes=scenes, lpips=not args.no_lpips,
                         checkpoint_every=args.checkpoint_every, eval_every=args.eval_every,
                         eval_objects=args.eval_objects, workers=args.workers, device=args.device)
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


def _run_eval(args: argparse.Namespace) -> int:
    from .evaluation.baselines import MeanColourSphere, untrained_model
    from .evaluation.carved_hull import CarvedHull
    from .evaluation.evaluate import EvalConfig

    _require_at_least_one(args, "objects", "updates", "output_views")
    _require_range(args, "size", VIEW_SIZE, " pixels")
    _require_range(args, "mesh_resolution", MESH_RESOLUTION, " samples per side")
    source = _model_with_warning(args.checkpoint)
    model = source.model
    config = EvalConfig(updates=args.updates, output_views=args.output_views, mesh_resolution=args.mesh_resolution)
    objects = _heldout_objects(args)
    training = source.extra.get("training", {})
    label = (args.checkpoint.name if args.checkpoint else source.description) + (
        f" (stage {training['stage']}, step {training['step']})" if training else "")
    contenders = [(label, model)]
    if args.baselines:
        contenders += [(f"untrained '{model.config.name}' (seed 0)", untrained_model(model.config)),
                       ("mean-colour sphere", MeanColourSphere(model.config.image_size, model.config.radius)),
                       ("carved visual hull", CarvedHull(model.config.image_size, radius=model.config.radius))]
    results = []
    relighter = None
    if not args.no_relight and any(o.relight is not None for o in objects):
        from .evaluation.relighting import Relighter

        relighter = Relighter()
    try:
        _evaluate_contenders(args, contenders, objects, config, model, relighter, results)
    finally:
        if relighter is not None:
            relighter.release()
    return _write_eval(args, results, label, model, objects, contenders, source)


def _evaluate_contenders(args, contenders, objects, config, model, relighter, results) -> None:
    from .evaluation.evaluate import evaluate_heldout

    for name, reconstructor in contenders:
        bar = _progress_bar(len(objects), f"evaluating {name}")
        bar.unit = "object"
        try:
            results.append((name, evaluate_heldout(reconstructor, objects, config, set_name=args.set, progress=_bar_updater(bar),
                                                   relighter=relighter)))
        finally:
            bar.close()
    if args.refine:
        from .evaluation.refined_rows import evaluate_refined
        from .refine.config import refine_preset

        if args.refine_minutes is not None and not args.refine_minutes > 0:
            raise LirmUsageError(f"--refine-minutes must be positive, got {args.refine_minutes}")
        refine = refine_preset("default", inverse_rendering=bool(args.materials),
                               **({"minutes": args.refine_minutes} if args.refine_minutes else {}))
        for name, init in (("refined from LIRM", "lirm"), ("refined from the hull", "hull")):
            bar = _progress_bar(len(objects), f"{name} ({refine.minutes:g} min each)")
            bar.unit = "object"
            try:
                results.append((name, evaluate_refined(model, objects, config, refine, init, set_name=args.set,
                                                       progress=_bar_updater(bar), relighter=relighter)))
            finally:
                bar.close()


def _write_eval(args, results, label, model, objects, contenders, source) -> int:
    from .evaluation.report import comparison_table, markdown_table
    from .io.atomic_files import atomic_write, atomic_write_json

    if len(results) == 1:
        table = markdown_table(results[0][1], f"{label}: '{model.config.name}' model")
    else:
        table = comparison_table(results, f"'{model.config.name}' model against the baselines")
    sensitivity = {}
    if len(objects) > 1 and all(o.surface is not None for o in objects):
        from .evaluation.input_sensitivity import input_sensitivity

        lines = ["", "Input sensitivity (prediction at an object's surface from its own first views vs another object's; "
                     "about 0 = the inputs are ignored):", "", "| reconstructor | albedo Δ | SDF Δ |", "|---|---|---|"]
        for name, reconstructor in contenders:
            s = input_sensitivity(reconstructor, objects)
            sensitivity[name] = {"albedo": s.albedo, "sdf": s.sdf, "pairs": s.pairs}
            lines.append(f"| {name} | {s.albedo:.4f} | {s.sdf:.4f} |")
        table += "\n".join(lines) + "\n"
    print(table)
    if args.out:
        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), {
            "checkpoint": str(args.checkpoint) if args.checkpoint else source.description,
            **results[0][1].to_dict(),
            "baselines": {name: result.to_dict() for name, result in results[1:]}, "input_sensitivity": sensitivity})
    return 0


def _run_bench_refine(args: argparse.Namespace) -> int:
    from .bench.refine_bench import apply_options, dumps, refine_bench_table, run_refine_bench
    from .evaluation.evaluate import EvalConfig
    from .io.atomic_files import atomic_write
    from .refine.config import refine_preset

    _require_at_least_one(args, "objects", "output_views")
    _require_range(args, "size", VIEW_SIZE, " pixels")
    if any(not m > 0 for m in args.minutes):
        raise LirmUsageError(f"--minutes must all be positive, got {args.minutes}")
    source = _model_with_warning(args.checkpoint)
    base = apply_options(refine_preset("default"), args.option)
    args.updates = 4
    objects = _heldout_objects(args)
    if args.warm_start:
        from .bench.refine_bench import run_warm_start_bench, warm_start_table

        bar = _progress_bar(len(objects), "warm and cold starts")
        try:
            result = run_warm_start_bench(source.model, objects, EvalConfig(output_views=args.output_views), base,
                                          args.minutes[0], progress=_bar_updater(bar))
        finally:
            bar.close()
        table = warm_start_table(result)
    else:
        bar = _progress_bar(len(args.minutes), "refinement budgets")
        try:
            result = run_refine_bench(source.model, objects, EvalConfig(output_views=args.output_views), base, args.minutes,
                                      args.init, progress=_bar_updater(bar))
        finally:
            bar.close()
        table = refine_bench_table(result, args.set)
    result["options"] = args.option
    print(table)
    if args.json:
        atomic_write(args.json, lambda tmp: tmp.write_text(dumps(result), encoding="utf-8"))
    return 0


def _run_bench_lighting(args: argparse.Namespace) -> int:
    from .bench.lighting_bench import run_lighting_bench

    if not (args.demo_out / "capture" / "capture.json").is_file() or not (args.demo_out / "truth" / "transforms.json").is_file():
        raise LirmUserError(f"{args.demo_out}: not a `lirm demo` output (it needs capture/ and truth/); run `lirm demo -o {args.demo_out}` first")
    print(run_lighting_bench(args.demo_out, args.env).report())
    return 0


def _run_bench_update_order(args: argparse.Namespace) -> int:
    from .bench.update_order_bench import run_update_order_bench, update_order_table
    from .evaluation.evaluate import EvalConfig
    from .io.atomic_files import atomic_write, atomic_write_json

    _require_at_least_one(args, "objects", "output_views")
    _require_range(args, "size", VIEW_SIZE, " pixels")
    source = _model_with_warning(args.checkpoint)
    args.set, args.updates = "synthetic", 3
    objects = _heldout_objects(args)
    bar = _progress_bar(4, "update orders")
    try:
        result = run_update_order_bench(source.model, objects, EvalConfig(updates=3, output_views=args.output_views,
                                                                          mesh_resolution=64), progress=_bar_updater(bar))
    finally:
        bar.close()
    table = update_order_table(result, [o.name for o in objects])
    print(table)
    if args.out:
        atomic_write(args.out, lambda tmp: tmp.write_text(table, encoding="utf-8"))
        atomic_write_json(args.out.with_suffix(".json"), result)
    return 0


def _run_ship(args: argparse.Namespace) -> int:
    from .train.ship import ship

    weights, card = ship(args.checkpoint, args.out, args.runs, args.eval, args.notes, args.note, args.hardware)
    print(f"wrote {weights} ({weights.stat().st_size / 2**20:.2f} MB) and {card}")
    return 0


def _heldout_objects(args: argparse.Namespace):
    from .evaluation.heldout_sets import capture_heldout, gltf_heldout, synthetic_heldout
    from .synth.asset_folders import scan_environment_folder, scan_model_folder
    from lirm.renderer.context import create_headless_context
    from lirm.renderer.pbr_renderer import PBRRenderer

    if args.set not in ("synthetic", "gltf"):
        capture = Path(args.set)
        if not capture.exists():
            raise LirmUsageError(f"--set {args.set}: not 'synthetic', 'gltf' or a capture folder (no such folder)")
        if not (capture / "capture.json").exists():
            raise LirmUserError(f"--set {args.set}: not 'synthetic', 'gltf' or a capture folder (no capture.json there)")
        return capture_heldout(capture, sets=args.updates)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        if args.set == "synthetic":
            return synthetic_heldout(renderer, args.objects, args.size)
        models, envs = scan_model_folder(args.models), scan_environment_folder(args.environments)
        for scan, what in ((models, "glTF models"), (envs, "environments")):
            if scan.problems:
                print(scan.report(what), file=sys.stderr)
        return gltf_heldout(renderer, models.usable, envs.usable, args.size)
    finally:
        renderer.release()
        ctx.release()


def _run_app(args: argparse.Namespace) -> int:
    import os

    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        raise LirmUserError("no display: `lirm app` needs a desktop session (or run it under xvfb-run); "
                            "`lirm demo` runs the whole flow without a window")
    from lirm.app.window import AppConfig, run_app

    config = AppConfig(capture=args.capture, demo=args.demo, width=args.size[0], height=args.size[1], checkpoint=args.checkpoint,
                       script=args.script, extra_environments=tuple(args.hdri), reopen_last=not args.new)
    run_app(config)
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    from dataclasses import replace

    from .demo import DemoConfig

    config = replace(DemoConfig(), capture_only=args.capture_only)
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
    if not result.trained:
        print("WARNING: no trained weights ship yet: the reconstruction and asset come from UNTRAINED weights and "
              "do not look like the mug", file=sys.stderr)
    return 0


def _run_bench_model(args: argparse.Namespace) -> int:
    from .bench.model_bench import ModelBenchConfig, run_model_bench

    if args.updates < 1 or args.views_per_update < 1:
        raise LirmUsageError("--updates and --views-per-update must be at least 1")
    config = ModelBenchConfig(preset=args.preset, updates=args.updates, views_per_update=args.views_per_update, device=args.device,
                              baseline=not args.no_baseline, baseline_max_views=args.baseline_max_views, json_path=args.json)
    result = run_model_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        print(f"figures written to {args.json}")
    return 0


def _run_bench_capacity(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .io.atomic_files import atomic_write_json
    from .io.images import to_uint8, write_png
    from .synth.object_views import ObjectViewsConfig
    from .train.overfit import OverfitConfig, comparison_sheet, render_training_views, run_overfit

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


def _run_bench_export(args: argparse.Namespace) -> int:
    import json

    from .bench.export_bench import ExportBenchConfig, RoundTripConfig, run_asset_round_trip, run_export_bench

    _check_export_options(args)
    _check_export_memory(args)
    if args.model:
        figures = run_asset_round_trip(RoundTripConfig(args.model, args.env, grid=args.grid, faces=args.faces,
                                                       texture=args.texture, sheet=args.sheet))
    else:
        figures = run_export_bench(ExportBenchConfig(args.grid, args.faces, args.texture))
    print(json.dumps(figures, indent=2))
    if args.json:
        from .io.atomic_files import atomic_write_json

        atomic_write_json(args.json, figures)
    return 0


def _run_bench_synth(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from .bench.synth_bench import SynthBenchConfig, run_synth_bench

    _require_at_least_one(args, "scenes", "views")
    _require_range(args, "size", (16, 2048), " pixels")
    base = SynthBenchConfig()
    config = replace(base, scenes=args.scenes, scene=replace(base.scene, views=args.views, size=args.size), sheet_path=args.sheet)
    result = run_synth_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if result.sheet:
        print(f"contact sheet: {result.sheet}")
    return 0


def _run_bench_capture(args: argparse.Namespace) -> int:
    from .bench.capture_bench import CaptureBenchConfig, run_capture_bench

    _require_range(args, "max_side", MAX_SIDE, " pixels")
    if not args.photos.is_dir():
        raise LirmUserError(f"{args.photos}: not a folder of photos")
    try:
        counts = tuple(int(s) for s in args.counts.split(","))
    except ValueError:
        raise LirmUsageError(f"--counts must be comma-separated integers, got {args.counts!r}") from None
    config = CaptureBenchConfig(args.photos, counts, args.max_side, args.masks)
    result = run_capture_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        from .io.atomic_files import atomic_write_json

        atomic_write_json(args.json, asdict(result))
    return 0


def _run_bench_render(args: argparse.Namespace) -> int:
    from .bench.render_bench import RenderBenchConfig, run_render_bench

    try:
        sizes = tuple(int(s) for s in args.sizes.split(","))
    except ValueError:
        raise LirmUsageError(f"--sizes must be comma-separated integers, got {args.sizes!r}") from None
    config = RenderBenchConfig(model=args.model, environment=args.env, sizes=sizes, frames=args.frames, ibl_preset=args.ibl)
    result = run_render_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        from .io.atomic_files import atomic_write_json

        atomic_write_json(args.json, asdict(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
