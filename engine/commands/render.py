"""`lirm render`: orbit renders of an asset (beauty, G-buffer, transforms.json)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import LirmUsageError
from .common import check_output, parse_size, view_progress_bar


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("render", help="render an asset from an orbit of cameras: beauty + G-buffer PNGs + transforms.json")
    parser.add_argument("asset", nargs="?", help="a .gltf/.glb/.obj file or a built-in object name (see --list)")
    parser.add_argument("--env", default="studio", help="built-in environment (studio, sky, overcast), an .hdr/.exr path, or a capture folder (the lighting its photos were taken in)")
    parser.add_argument("--views", type=int, default=8, help="number of orbit views (default 8)")
    parser.add_argument("--size", type=parse_size, default=(512, 512), help="image size WxH (default 512x512)")
    parser.add_argument("-o", "--out", type=Path, help="output folder (required)")
    parser.add_argument("--elevation", type=float, default=20.0, help="camera elevation in degrees (default 20)")
    parser.add_argument("--fov", type=float, default=40.0, help="field of view of the shorter image side, degrees (default 40)")
    parser.add_argument("--exposure", type=float, default=0.0, help="camera exposure in EV (default 0)")
    parser.add_argument("--env-rotation", type=float, default=0.0, help="environment rotation about +Z in degrees")
    parser.add_argument("--supersample", type=int, default=2, choices=[1, 2, 3, 4], help="anti-aliasing factor (default 2)")
    parser.add_argument("--no-background", action="store_true", help="transparent background (RGBA beauty)")
    parser.add_argument("--keep-scale", action="store_true", help="do not fit the asset into the unit sphere")
    parser.add_argument("--cameras", type=Path, metavar="TRANSFORMS_JSON|CAPTURE",
                        help="render from exactly these cameras (a transforms.json, e.g. one this command wrote) with the "
                             "asset in its own frame (not refitted), so that an original and its reconstruction compare "
                             "view for view; or a capture folder: its photos' cameras, moved to where the export placed "
                             "the asset, to set each render beside its photo; --views, --size, --elevation and --fov "
                             "are then unused")
    parser.add_argument("--ibl", default="default", choices=["default", "preview", "high"],
                        help="environment filtering quality: preview is faster on a CPU, high is finer on a GPU")
    parser.add_argument("--list", action="store_true", help="list the built-in objects and environments and exit")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS
    from lirm.renderer.pbr_renderer import PBRRenderer
    from lirm.renderer.context import create_headless_context

    from ..assets.asset_source import resolve_asset
    from ..assets.environment_files import resolve_environment
    from ..orbit_render import OrbitRenderConfig, render_orbit
    from ..synth.procedural_objects import BUILTIN_OBJECTS

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
    check_output(args.out, "the output folder (-o)", folder=True)
    model = resolve_asset(args.asset)
    environment = resolve_environment(args.env)
    from dataclasses import replace

    from ..lighting.camera_response import TONE_CURVE_OF_RESPONSE
    from ..lighting.capture_lighting import camera_response_of

    response = camera_response_of(args.env)  # a capture read through plain sRGB is shown through it under its own light
    config = replace(config, tonemapper=TONE_CURVE_OF_RESPONSE[response])
    cameras = None
    if args.cameras is not None:
        from ..orbit_render import MAX_RENDER_SIDE, cameras_from_transforms

        if args.cameras.is_dir():
            from ..orbit_render import cameras_of_capture

            cameras = cameras_of_capture(args.cameras, args.asset)
        else:
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
        with view_progress_bar(config.views, "rendering") as bar:
            result = render_orbit(renderer, model, environment, config, args.out, progress=lambda done, total: bar.update(1),
                                  cameras=cameras)
    finally:
        renderer.release()
        ctx.release()
    curve = " (shown through plain sRGB, as its photos were read)" if response == "srgb" else ""
    print(f"wrote {len(result.cameras)} views of {model.source.name} under {environment.name}{curve} to {result.out_dir}/")
    print("  beauty/ radiance/ albedo/ roughness/ metallic/ normal/ depth/ mask/ transforms.json")
    return 0
