"""What the user is told after a capture: per file, per frame, and what to do next."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..lighting.capture_lighting import last_lighting_stage_entry
from .pipeline import CaptureSummary


def format_capture_report(summary: CaptureSummary, reference: Path | None = None) -> str:
    capture = summary.capture
    lines = [f"capture: {capture.root}"]
    skipped = [r for r in capture.reports if not r.accepted]
    lines.append(f"  photos accepted: {summary.accepted}, skipped: {len(skipped)}")
    for r in skipped:
        lines.append(f"    skipped {Path(r.path).name}: {r.reason}")
    lines.append(f"  posed: {summary.registered} of {summary.accepted} ({capture.settings.get('pose_source', 'not posed')})")
    for frame_id, state in sorted(capture.frames.items()):
        if state.pose_status != "registered":
            lines.append(f"    {state.record.original.name} ({frame_id}): {state.pose_status}")
    lens_line = _lens_line(capture.records)
    if lens_line:
        lines.append(lens_line)
    exposure_line = _exposure_line(capture)
    if exposure_line:
        lines.append(exposure_line)
    focal_note = _focal_check_of_last_pose(capture.history)
    if focal_note:  # COLMAP's model disagreed with the lens (focal_check.py)
        lines.append(f"  focal length: {focal_note}")
    points_for_imported = [e for e in capture.history if e.get("action") == "points for imported poses"]
    if points_for_imported:  # imported poses with automatic masks: where their seeds came from, or why none did
        lines.append(f"  points for the automatic masks: {points_for_imported[-1].get('note')}")
    lines.append(f"  masks ok: {summary.masked} of {summary.registered}")
    for frame_id, state in sorted(capture.frames.items()):
        if frame_id in capture.cameras and state.mask_status != "ok":
            lines.append(f"    {state.record.original.name} ({frame_id}): mask {state.mask_status}")
    warned = [(f, s) for f, s in sorted(capture.frames.items()) if f in capture.cameras and s.mask_status == "ok" and s.mask_warning]
    if warned:
        lines.append(f"  masks used with a warning: {len(warned)} (check them in masks/; `lirm capture --fix-mask` corrects one)")
        for frame_id, state in warned:
            lines.append(f"    {state.record.original.name} ({frame_id}): {state.mask_warning}")
    lines.append(f"  network views prepared: {summary.prepared}")
    lines.append(_lighting_line(capture))
    timings = capture.settings.get("timings", {})
    if summary.nothing_new:
        lines.append("  nothing new was added (every photo was skipped, see above): no stage ran and the capture is unchanged")
    elif timings:
        lines.append("  seconds: " + ", ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    if reference is not None and summary.registered:
        lines.append(_reference_errors(capture, reference))
    if not summary.usable:
        lines.append("  nothing could be posed: take photos with more overlap (about 20-30 degrees between shots), "
                     "more texture in view, or pass known poses with --poses")
    elif summary.prepared == 0 and "crops" in capture.settings.get("completed", []):
        lines.append("  no view could be prepared, so there is nothing to reconstruct: every mask failed (see above); "
                     "look at masks/, correct one with `lirm capture --fix-mask`, or pass your own with --masks FOLDER")
    elif summary.registered < summary.accepted:
        lines.append("  the photos that did not register can be retaken or removed; the capture is usable without them")
    return "\n".join(lines)


def _lighting_line(capture) -> str:
    last = last_lighting_stage_entry(capture.history)
    if last is None:
        return "  lighting as photographed: not estimated yet (`lirm capture --resume` estimates it)"
    if not last.get("estimated"):
        return f"  lighting as photographed: none ({last.get('reason', 'no background')})"
    return (f"  lighting as photographed: {last['file']} from the backgrounds of {last['photos']} photos; "
            f"{100 * last['seen']:.0f}% of directions seen (the rest filled smoothly, not measured), "
            f"{100 * last['clipped']:.0f}% of the seen ones clipped"
            + (f"; the photos read as plain sRGB ({last.get('camera_response_why')})" if last.get("camera_response") == "srgb" else ""))


def _lens_line(records) -> str | None:
    """What the photos' EXIF said of the lens (exif_focal.py), when any photo has it: focal lengths
    within LENS_TOLERANCE of each other are one lens (portrait and landscape photos included)."""
    from .exif_focal import split_by_lens

    focals = [r.focal_prior_px for r in records if r.focal_prior_px]
    if not focals:
        return None
    lenses = split_by_lens(focals)
    shown = ", ".join(f"{round(float(np.median(lens)))} px" for lens in lenses)
    return (f"  focal length from EXIF: {len(focals)} of {len(records)} photos, {len(lenses)} "
            f"lens{'es' if len(lenses) > 1 else ''} ({shown} in the working images)")


def _exposure_line(capture) -> str | None:
    """How far apart the photos' exposures were (exif_exposure.py), with the fix when the camera's
    automatic exposure moved enough to show as the object's brightness; for photos whose EXIF does
    not say, what their backgrounds said (exposure_estimate.py)."""
    from .exif_exposure import exposure_note
    from .exposure_match import estimated_exposure_note, white_balance_note

    lines = []
    note = exposure_note([r.exposure_stops for r in capture.records])
    if note:
        lines.append(f"  exposure from EXIF: {note[0]}")
    estimated = estimated_exposure_note(capture)
    if estimated:
        lines.append(f"  exposure from the photos' shared backgrounds (their EXIF does not say): {estimated[0]}")
    balance = white_balance_note(capture)
    if balance:
        lines.append(f"  white balance from the photos' shared backgrounds: {balance[0]}")
    return "\n".join(lines) or None


def _focal_check_of_last_pose(history: list[dict]) -> str | None:
    """The focal length check's note of the latest posing (logged just before its "pose" entry)."""
    pending = current = None
    for entry in history:
        if entry.get("action") == "focal length check":
            pending = entry.get("note")
        elif entry.get("action") == "pose":
            current, pending = pending, None
    return current


def _reference_errors(capture, reference: Path) -> str:
    from .alignment import pose_errors
    from .pose_import import import_transforms_json

    truth = import_transforms_json(reference, capture.records)
    e = pose_errors(capture.cameras, truth.cameras)
    return (f"  against {reference} ({e['num_frames']} frames, after a similarity alignment): rotation error median "
            f"{e['rotation_deg_median']:.3f} deg, max {e['rotation_deg_max']:.3f} deg; camera-centre error median "
            f"{100 * e['center_error_median']:.2f}%, max {100 * e['center_error_max']:.2f}% of the scene size; "
            f"focal ratio {e['focal_ratio']:.4f}")
