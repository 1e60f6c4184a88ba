"""`lirm export`: a capture's reconstruction as a textured PBR .glb (or .usdz)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError
from .common import check_export_memory, check_export_options, check_output, require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("export", help="the capture's latest reconstruction as a textured PBR .glb")
    parser.add_argument("capture", type=Path, help="a capture folder with a reconstruction (`lirm reconstruct`)")
    parser.add_argument("-o", "--out", type=Path, help="the .glb (or .usdz, for Apple's AR Quick Look) to write (default "
                        "CAPTURE/export/asset.glb, as the app; replaced only by a complete file)")
    parser.add_argument("--faces", type=int, default=20_000, help="face budget after decimation (default 20000)")
    parser.add_argument("--texture", type=int, default=1024,
                        help="texture side in pixels, 64..4096 (default 1024; where it is finer than the photos, the fit "
                             "to them runs at their resolution and its change is carried up)")
    parser.add_argument("--grid", type=int, default=256, help="marching-cubes grid per side (default 256)")
    parser.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    parser.add_argument("--no-normal-map", action="store_true", help="leave out the tangent-space normal map")
    parser.add_argument("--obj", action="store_true", help="also write NAME.obj + NAME.mtl + PNG textures beside the .glb")
    parser.add_argument("--usdz", action="store_true", help="also write NAME.usdz beside the .glb (the same mesh and textures)")
    parser.add_argument("--update", type=int, help="export the state after this update (default: the latest)")
    parser.add_argument("--no-texture-fit", action="store_true",
                        help="keep the field's baked textures: do not fit them to the photos afterwards (done by default for a "
                             "state refined with materials, `lirm refine --materials`)")
    parser.add_argument("--register-photos", action="store_true",
                        help="before fitting the textures, register each photo to the export by a smooth warp of up to 3 px "
                             "(for photos whose poses are a little off; measured worth nothing on exactly posed photos)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..export.capture_export import export_capture
    from ..export.export_asset import ExportConfig
    from ..export.field_mesh import MeshExtractionConfig

    check_export_options(args)
    if args.register_photos and args.no_texture_fit:
        raise LirmUsageError("--register-photos registers the photos for the texture fit, which --no-texture-fit turns off: "
                             "leave out one of them")
    require_capture(args.capture)
    if args.out is None:
        args.out = args.capture / "export" / "asset.glb"
        args.out.parent.mkdir(parents=True, exist_ok=True)
    check_output(args.out, "the asset (-o)", make_parents=False, example=f"{args.capture.name or 'asset'}.glb")
    if args.obj:
        check_output(args.out.with_suffix(".obj"), "the OBJ copy (--obj)", make_parents=False)
    if args.usdz and args.out.suffix.lower() == ".glb":
        check_output(args.out.with_suffix(".usdz"), "the USDZ copy (--usdz)", make_parents=False)
    check_export_memory(args)
    config = ExportConfig(mesh=replace(MeshExtractionConfig(), resolution=args.grid, face_budget=args.faces),
                          texture_size=args.texture, normal_map=not args.no_normal_map, obj=args.obj,
                          usdz=args.usdz, **_texture_fit_setting(args))
    result, source = export_capture(args.capture, args.out, config, args.checkpoint,
                                    progress=_export_progress, update=args.update)
    from ..capture.capture_folder import Capture
    from ..export.capture_export import chosen_entry

    capture = Capture.open(args.capture)
    # Whether the step exported is a refinement (fitted to the photos, not the weights' alone).
    refined = chosen_entry(capture, args.update).get("kind") == "refine"
    if not source.trained:
        print(f"WARNING: exported from UNTRAINED weights ({source.description}): the asset does not look like the object", file=sys.stderr)
    elif source.note and not refined:
        # The caveat about the shipped weights, as every command that uses them prints it.
        print(f"about these weights: {source.note}", file=sys.stderr)
    timings = ", ".join(f"{k} {v:.1f} s" for k, v in result.seconds.items())
    print(f"{result.path}: {result.faces} faces, {result.vertices} vertices, {result.texture_size}px textures ({timings})")
    if result.texture_fit is not None:
        print(result.texture_fit.summary())
    elif refined and not args.no_texture_fit:
        print("textures: the field's own (baked); they are fitted to the photos only for a state refined with materials "
              "(`lirm refine --materials`)")
    real = capture.settings.get("real_size")
    if real:
        which, metres = next(iter(real.items()))
        print(f"in metres: the object's {which} is {metres:g} m as stated; its base is on y = 0")
    else:
        print(f"note: the scale is arbitrary (the photos' units); give the real size with "
              f"`lirm capture --real-size height=METRES {args.capture}` to export in metres")
    return 0


def _export_progress(stage: str, done: int, total: int) -> None:
    progress_events.emit(stage, done, total)
    print(f"[{done}/{total}] {stage}", file=sys.stderr)


def _texture_fit_setting(args: argparse.Namespace) -> dict:
    """ExportConfig's texture_fit as the options ask (nothing: its default)."""
    from ..export.photo_texture_fit import TextureFitConfig

    if args.no_texture_fit:
        return {"texture_fit": None}
    if args.register_photos:
        return {"texture_fit": TextureFitConfig(register_grid=REGISTER_GRID)}
    return {}


REGISTER_GRID = 4  # nodes per side of each photo's warp lattice (README, "Registering the photos")
