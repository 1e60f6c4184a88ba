"""The `lirm` command line. Each subcommand maps onto a dataclass config; only built features appear."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from dataclasses import asdict
from pathlib import Path

from lirm.renderer.context import GLContextError

from .errors import LirmUserError


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging(args.verbose)
    try:
        return args.run(args)
    except (LirmUserError, GLContextError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cancelled", file=sys.stderr)
        return 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="lirm", description="LIRM Studio: photos of an object to a relightable 3D asset.")
    parser.add_argument("-v", "--verbose", action="store_true", help="more logging")
    sub = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)

    demo = sub.add_parser("demo", help="run the main job on built-in data (renders the built-in objects for now)")
    demo.add_argument("-o", "--out", type=Path, default=Path("demo_output"), help="output folder (default: ./demo_output)")
    demo.set_defaults(run=_run_demo)

    render = sub.add_parser("render", help="render an asset from an orbit of cameras: beauty + G-buffer PNGs + transforms.json")
    render.add_argument("asset", nargs="?", help="a .gltf/.glb/.obj file or a built-in object name (see --list)")
    render.add_argument("--env", default="studio", help="built-in environment (studio, sky, overcast) or an .hdr/.exr path")
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
    render.add_argument("--ibl", default="default", choices=["default", "preview", "high"],
                        help="environment filtering quality: preview is faster on a CPU, high is finer on a GPU")
    render.add_argument("--list", action="store_true", help="list the built-in objects and environments and exit")
    render.set_defaults(run=_run_render)

    bench = sub.add_parser("bench", help="benchmarks")
    bench_sub = bench.add_subparsers(title="benchmarks", metavar="BENCH", required=True)
    br = bench_sub.add_parser("render", help="renderer speed: environment preprocessing and G-buffer frames per second")
    br.add_argument("--model", default="vase", help="model file or built-in object (the issue's figures use DamagedHelmet)")
    br.add_argument("--env", default="studio", help="built-in environment or .hdr/.exr (the issue's figures use a 1k HDR)")
    br.add_argument("--sizes", default="512,1024", help="square image sizes, comma separated")
    br.add_argument("--frames", type=int, default=20, help="frames per size")
    br.add_argument("--ibl", default="default", choices=["default", "preview", "high"], help="environment filtering preset")
    br.add_argument("--json", type=Path, help="also write the results as JSON here")
    br.set_defaults(run=_run_bench_render)
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


def _progress_bar(total: int, desc: str):
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="view", file=sys.stderr, disable=None)


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
        raise LirmUserError("lirm render needs an ASSET and -o OUT_DIR (lirm render --list shows the built-in assets)")
    try:
        config = OrbitRenderConfig(
            views=args.views, width=args.size[0], height=args.size[1], elevation_deg=args.elevation, fov_deg=args.fov,
            supersample=args.supersample, background=not args.no_background, exposure_ev=args.exposure,
            environment_rotation_deg=args.env_rotation, normalize=not args.keep_scale,
        )
    except ValueError as err:
        raise LirmUserError(str(err)) from None
    model = resolve_asset(args.asset)
    environment = resolve_environment(args.env)
    from lirm.renderer.ibl import IBL_PRESETS

    ctx = create_headless_context()
    renderer = PBRRenderer(ctx, IBL_PRESETS[args.ibl])
    try:
        with _progress_bar(config.views, "rendering") as bar:
            result = render_orbit(renderer, model, environment, config, args.out, progress=lambda done, total: bar.update(1))
    finally:
        renderer.release()
        ctx.release()
    print(f"wrote {len(result.cameras)} views of {model.source.name} under {environment.name} to {result.out_dir}/")
    print("  beauty/ radiance/ albedo/ roughness/ metallic/ normal/ depth/ mask/ transforms.json")
    return 0


def _run_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    result = run_demo(args.out, progress=lambda message: print(message, file=sys.stderr))
    print(f"demo pictures are in {result.out_dir.resolve()}/")
    print(f"  overview of every built-in object under every built-in environment: {result.overview}")
    for env_name, folder in result.orbit_dirs.items():
        print(f"  orbit under {env_name}: {folder}/beauty/ (and its G-buffer channels beside it)")
    return 0


def _run_bench_render(args: argparse.Namespace) -> int:
    from .bench.render_bench import RenderBenchConfig, run_render_bench

    try:
        sizes = tuple(int(s) for s in args.sizes.split(","))
    except ValueError:
        raise LirmUserError(f"--sizes must be comma-separated integers, got {args.sizes!r}") from None
    config = RenderBenchConfig(model=args.model, environment=args.env, sizes=sizes, frames=args.frames, ibl_preset=args.ibl)
    result = run_render_bench(config, progress=lambda message: print(message, file=sys.stderr))
    print(result.table())
    if args.json:
        from .io.atomic_files import atomic_write_json

        atomic_write_json(args.json, asdict(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
