"""`lirm suggest`: where to shoot next."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import check_output, require_at_least_one, require_capture


def add_parser(subparsers) -> None:
    parser = subparsers.add_parser("suggest", help="where to shoot next: ranked views, a sentence each, and a view-sphere heat map")
    parser.add_argument("capture", type=Path, help="a capture folder (with or without a reconstruction)")
    parser.add_argument("--k", type=int, default=4, help="how many views to suggest (default 4)")
    parser.add_argument("--can-turn", action="store_true", help="the object can be turned over: also suggest views from below "
                        "it (by default, an object standing on something is only shot from above)")
    parser.add_argument("--heat-map", type=Path, help="write the view-sphere heat map here (default CAPTURE/guidance/heat_map.png)")
    parser.add_argument("--checkpoint", type=Path, help="the weights the reconstruction was made with (default: as lirm reconstruct)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..guidance.suggest import suggest_for_capture, write_guidance, write_heat_map
    from lirm.renderer.context import create_headless_context

    require_at_least_one(args, "k")
    require_capture(args.capture)
    if args.heat_map is not None:
        check_output(args.heat_map, "the heat map (--heat-map)", example="heat_map.png")
    check_output(args.capture / "guidance", "the capture's guidance folder", folder=True)
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
