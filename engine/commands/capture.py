"""`lirm capture`: photos, a video or a camera into a capture folder; and the edits of a capture
(--add, --resume, --fix-mask, --undo-fix-mask, --real-size, --check)."""

from __future__ import annotations

import argparse
from pathlib import Path

from .. import progress_events
from ..errors import LirmUsageError, LirmUserError
from ..progress_lines import progress_bar
from .common import CAPTURE_SIZE, MAX_SIDE, check_memory, check_output, require_capture, require_range


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("capture", help="photos, a video or a camera -> a posed, masked, cropped capture folder")
    parser.add_argument("inputs", help="a folder of photos, a video file, or camera:N for live camera N; with --add, the photos to add")
    parser.add_argument("capture", nargs="?", type=Path, help="with --add: the capture folder to extend")
    parser.add_argument("-o", "--out", type=Path, help="the capture folder to create")
    parser.add_argument("--add", action="store_true", help="add the photos in INPUTS to the existing capture CAPTURE")
    parser.add_argument("--resume", action="store_true", help="INPUTS is an interrupted capture folder: finish its remaining stages")
    parser.add_argument("--reference-originals", action="store_true",
                        help="refer to the original photos where they are instead of copying them into the capture")
    parser.add_argument("--fix-mask", metavar="FRAME_ID", help="INPUTS is a corrected mask (PNG, 255 = object) for this frame of "
                        "CAPTURE; the correction propagates to the other views")
    parser.add_argument("--real-size", metavar="height=M|width=M", help="INPUTS is a capture: the object's real height (or "
                        "largest width), e.g. height=0.095 or height=9.5cm; every export is then in metres")
    parser.add_argument("--check", action="store_true", help="INPUTS is a capture: check its files against capture.json, "
                        "make again what can be (crops, masks) and name what cannot")
    parser.add_argument("--undo-fix-mask", action="store_true", help="INPUTS is a capture: put back the masks the last --fix-mask replaced")
    parser.add_argument("--poses", help="use known poses: a transforms.json (NeRF, instant-ngp, nerfstudio) or a COLMAP model folder")
    parser.add_argument("--masks", default="auto", help="auto (alpha if every photo has one, else automatic), alpha, automatic, or a folder of masks")
    parser.add_argument("--camera-response", choices=("auto", "aces", "srgb"), default="auto",
                        help="the tone curve the photos are read through for their lighting and materials: aces (the "
                        "app's display transform), srgb (a plain decode), or auto (default): aces, but srgb for a "
                        "plain backdrop photographed clipped (a white sweep exposed to pure white)")
    parser.add_argument("--max-side", type=int, default=1280, help="long side of the working images (default 1280)")
    parser.add_argument("--size", type=int, default=256, help="side of the network's square crops (default 256)")
    parser.add_argument("--reference", type=Path, help="report pose errors against this transforms.json (for known test scenes)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..capture.capture_lock import capture_lock
    from ..capture.pipeline import CaptureConfig, add_to_capture, run_capture
    from ..capture.report import format_capture_report
    from ..resources import crop_bytes

    require_range(args, "size", CAPTURE_SIZE, " pixels")
    require_range(args, "max_side", MAX_SIDE, " pixels")
    if args.resume or args.add:  # an existing capture (not one? require_capture says so below)
        existing = Path(args.inputs) if args.resume else args.capture
        if existing is not None and existing.is_dir():
            check_output(existing, "the capture folder", folder=True)
    elif not (args.fix_mask or args.check or args.undo_fix_mask) and args.out is not None:
        check_output(args.out, "the capture folder (-o)", folder=True)
    check_memory(args, [("--size", CAPTURE_SIZE, crop_bytes)])
    config = CaptureConfig(masks=args.masks, poses=args.poses, camera_response=args.camera_response)
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

        from ..capture.pipeline import fix_mask

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
        from ..capture.real_size import parse_real_size, set_real_size

        require_capture(Path(args.inputs))
        try:
            which, metres = parse_real_size(args.real_size)
        except ValueError as err:
            raise LirmUsageError(f"--real-size {err}") from None
        set_real_size(args.inputs, which, metres)
        print(f"{args.inputs}: the object is {metres:g} m {'tall' if which == 'height' else 'wide'}; exports are in metres from now on")
        return 0
    if args.check or args.resume:
        from ..capture.capture_check import check_capture

        require_capture(Path(args.inputs))
        with capture_lock(args.inputs, "lirm capture --check"):
            checked = check_capture(args.inputs)
        if args.check or not checked.clean:
            print("\n".join(checked.lines()))
        if args.check:
            return 0 if not checked.unrepairable else 1
    if args.undo_fix_mask:
        from ..capture.mask_fix import undo_mask_fix

        with capture_lock(args.inputs, "lirm capture --undo-fix-mask"):
            restored = undo_mask_fix(args.inputs, config.crop)
        print(f"masks put back as they were before the last correction: {', '.join(restored)}")
        return 0
    try:
        if args.resume:
            from ..capture.pipeline import resume_capture

            with capture_lock(args.inputs, "lirm capture --resume"):
                summary = resume_capture(Path(args.inputs), config, progress=progress)
        elif args.add:
            if args.capture is None:
                raise LirmUsageError("lirm capture --add PHOTOS CAPTURE: name the capture folder to extend")
            require_capture(args.capture)
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
