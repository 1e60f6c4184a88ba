"""What several commands share: the accepted ranges of the options that size the work, the checks
made before any work starts (each refusal a LirmUsageError, LirmUserError or LirmResourceError that
`lirm.engine.cli.main` turns into a sentence and an exit code), progress bars and the held-out sets."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError, LirmUserError
from ..progress_lines import progress_bar

# Accepted ranges of the options that size the work (checked before any work starts).
CAPTURE_SIZE = (32, 2048)  # lirm capture --size
MAX_SIDE = (64, 16384)  # lirm capture --max-side
RENDER_SIZE = (8, 4096)  # reconstruct/refine --render-size
GRID_RESOLUTION = (16, 1024)  # reconstruct/refine --grid-resolution
EXPORT_GRID = (16, 1024)  # export --grid, bench export --grid
TEXTURE = (64, 4096)  # export --texture
VIEW_SIZE = (16, 1024)  # eval and bench --size (protocol views)
MESH_RESOLUTION = (16, 1024)  # eval and bench --mesh-resolution


def parse_size(text: str) -> tuple[int, int]:
    """The argparse type of --size WxH: '512x512' -> (512, 512)."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 512x512, got {text!r}") from None
    return w, h


# ---- checks before any work starts ---------------------------------------------------------------

def require_at_least_one(args: argparse.Namespace, *names: str) -> None:
    """Refuse counts below 1 (None means "not given" and passes)."""
    for name in names:
        value = getattr(args, name)
        if value is not None and value < 1:
            raise LirmUsageError(f"--{name.replace('_', '-')} must be at least 1, got {value}")


def require_range(args: argparse.Namespace, name: str, accepted: tuple[int, int], unit: str = "") -> None:
    """Refuse an option value outside `accepted` (inclusive; None means "not given" and passes)."""
    value = getattr(args, name)
    low, high = accepted
    if value is not None and not low <= value <= high:
        raise LirmUsageError(f"--{name.replace('_', '-')} must be between {low} and {high}{unit}, got {value}")


def check_memory(args: argparse.Namespace, needs: list[tuple[str, tuple[int, int], object]], together: bool = True) -> None:
    """Refuse (LirmResourceError) settings whose memory does not fit in the memory available now;
    `needs`: (option, accepted range, bytes as a function of its value) per memory-hungry option."""
    from .. import resources

    resources.check_memory(args.command, [resources.MemoryNeed(option, getattr(args, option.lstrip("-").replace("-", "_")),
                                                               bytes_for, accepted[0])
                                          for option, accepted, bytes_for in needs], together=together)


def check_render_options(args: argparse.Namespace) -> None:
    require_range(args, "render_size", RENDER_SIZE, " pixels")
    require_range(args, "grid_resolution", GRID_RESOLUTION, " voxels per side")


def check_render_memory(args: argparse.Namespace) -> None:
    """reconstruct/refine: the occupancy grid and one picture's buffers are held together."""
    from ..resources import occupancy_grid_bytes, render_bytes

    check_memory(args, [("--render-size", RENDER_SIZE, render_bytes), ("--grid-resolution", GRID_RESOLUTION, occupancy_grid_bytes)])


def check_export_options(args: argparse.Namespace) -> None:
    require_range(args, "grid", EXPORT_GRID, " samples per side")
    require_range(args, "texture", TEXTURE, " pixels")
    if args.faces < 100:
        raise LirmUsageError(f"--faces must be at least 100, got {args.faces}")


def check_export_memory(args: argparse.Namespace) -> None:
    """export: the marching-cubes grid, then (after it is freed) the texture bake."""
    from ..resources import bake_bytes, mesh_grid_bytes

    check_memory(args, [("--grid", EXPORT_GRID, mesh_grid_bytes), ("--texture", TEXTURE, bake_bytes)], together=False)


def add_gltf_set_arguments(parser: argparse.ArgumentParser) -> None:
    """`--models` and `--environments`: where the glTF set's models and HDRIs are (lirm eval, lirm
    bench refine, lirm train-materials); heldout_objects reads them."""
    parser.add_argument("--models", type=Path, default=Path("../shared/data/pbr_models"), help="glTF folder of the gltf set")
    parser.add_argument("--environments", type=Path, default=Path("../shared/data/envmaps"), help="HDR folder of the gltf set")


def add_first_object_argument(parser: argparse.ArgumentParser) -> None:
    """`--first-object K` (lirm eval, lirm bench refine); check_first_object refuses what it cannot mean."""
    parser.add_argument("--first-object", type=int, default=0, metavar="K",
                        help="the synthetic set's objects K .. K + N - 1 (default 0); the defaults were chosen on objects 0-3, "
                             "so objects from 4 on say whether a setting holds beyond them")


def check_first_object(args: argparse.Namespace) -> None:
    require_range(args, "first_object", (0, 10_000))
    if args.first_object and args.set != "synthetic":
        raise LirmUsageError(f"--first-object picks objects of the synthetic set; --set {args.set} takes all of its objects")


def check_output(path: Path, what: str, **kwargs) -> None:
    from ..io.output_paths import check_writable_output

    check_writable_output(path, what, **kwargs)


def require_capture(folder: Path) -> None:
    if not (folder / "capture.json").exists():
        from ..capture.photo_formats import is_photo

        photos = folder.is_dir() and any(is_photo(p) for p in folder.iterdir())
        if photos:  # a photo folder given where a capture was expected: capture it into a new folder
            target = folder.parent / f"{folder.name}_capture"
            raise LirmUserError(f"{folder} holds photos, not a capture (no capture.json); make a capture of them first "
                                f"with `lirm capture {folder} -o {target}` and use {target}")
        raise LirmUserError(f"{folder} is not a capture folder (no capture.json); make one with `lirm capture PHOTOS -o {folder}`")


# ---- what several commands use while they run -------------------------------------------------------

def model_with_warning(checkpoint):
    """The model to use (see model/pretrained.py), its untrained warning shown on stderr."""
    from ..model.pretrained import load_model

    source = load_model(checkpoint)
    if source.warning:
        print(source.warning, file=sys.stderr)
    return source


def bar_updater(bar):
    """A (message, done, total) progress callback that moves a tqdm bar and emits progress events."""
    def progress(message: str, done: int, total: int) -> None:
        progress_events.emit(message, done, total)
        bar.n = done
        bar.set_description(message)
        bar.refresh()
    return progress


def view_progress_bar(total: int, desc: str):
    return progress_bar(desc, total, unit="view")


def heldout_objects(args: argparse.Namespace):
    """The held-out objects of `--set` (synthetic, gltf or a capture folder): eval, bench refine, bench update-order."""
    from ..evaluation.heldout_sets import capture_heldout, gltf_heldout, synthetic_heldout
    from ..synth.asset_folders import scan_environment_folder, scan_model_folder
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
            return synthetic_heldout(renderer, args.objects, args.size, relight_gbuffers=getattr(args, "swap_study", False),
                                     first=getattr(args, "first_object", 0))
        models, envs = scan_model_folder(args.models), scan_environment_folder(args.environments)
        for scan, what in ((models, "glTF models"), (envs, "environments")):
            if scan.problems:
                print(scan.report(what), file=sys.stderr)
        return gltf_heldout(renderer, models.usable, envs.usable, args.size, relight_gbuffers=getattr(args, "swap_study", False))
    finally:
        renderer.release()
        ctx.release()
