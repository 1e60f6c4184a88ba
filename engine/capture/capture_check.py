"""A capture folder checked against its capture.json: what is missing or damaged, what can be made
again from what is there, and what cannot.

- a prepared crop (prepared/*.npz) missing or unreadable: cut again from the working image and mask;
- a mask missing: made again from the photo's alpha (alpha masks), from the user's mask folder
  (user masks), or by the automatic masking of all the views (only the missing ones are written);
  a mask the user corrected by hand (fixed) cannot be made again;
- a working image missing or unreadable: cannot be made again here (`lirm capture --add` with the
  original photo re-imports it);
- a reconstruction step whose state file is missing: cannot be made again (run the update again).

`lirm capture --check CAPTURE` runs it; `lirm capture --resume` and the commands that read the
prepared views run it on start, so a damaged capture is repaired or named, never silently smaller.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .capture_folder import Capture
from .crop import CropConfig, EmptyMaskError, prepare_view
from .exposure_match import capture_exposure_gains, capture_response, exposure_matched_image
from .masks import load_user_masks, mask_from_alpha


@dataclass
class CheckReport:
    repaired: list[str] = field(default_factory=list)  # sentences: what was made again
    unrepairable: list[str] = field(default_factory=list)  # sentences: what is lost, and what to do

    @property
    def clean(self) -> bool:
        return not self.repaired and not self.unrepairable

    def lines(self) -> list[str]:
        if self.clean:
            return ["capture checked: every file capture.json lists is there and readable"]
        return ([f"  repaired: {r}" for r in self.repaired] + [f"  cannot be repaired: {u}" for u in self.unrepairable])


def check_capture(root: str | Path, repair: bool = True) -> CheckReport:
    capture = Capture.open(root)
    report = CheckReport()
    crop = _crop_config(capture)
    posed = sorted(capture.cameras)
    completed = capture.settings.get("completed", [])

    unreadable_images = [f for f in posed if not _image_readable(capture, f)]
    for f in unreadable_images:
        name = capture.frames[f].record.original.name
        report.unrepairable.append(f"{f} ({name}): the working image {capture.image_path(f).relative_to(capture.root)} is "
                                   f"missing or unreadable; add the original photo again with `lirm capture --add`")

    if "masks" in completed:
        missing_masks = [f for f in posed if capture.frames[f].mask_status == "ok" and not capture.mask_path(f).is_file()
                         and f not in unreadable_images]
        if missing_masks:
            made = _remake_masks(capture, missing_masks) if repair else {}
            for f in missing_masks:
                if f in made:
                    capture.write_mask(f, made[f], source=capture.frames[f].mask_source or "auto", status="ok")
                    capture.prepared_path(f).unlink(missing_ok=True)  # cut again below from the new mask
                    report.repaired.append(f"{f}: mask made again ({capture.frames[f].mask_source})")
                else:
                    capture.frames[f].mask_status = "missing: the mask file was deleted"
                    capture.prepared_path(f).unlink(missing_ok=True)
                    report.unrepairable.append(f"{f}: its {capture.frames[f].mask_source or ''} mask file is gone; correct the "
                                               f"mask again with `lirm capture --fix-mask {f} MASK.png {capture.root}`")

    if "crops" in completed:
        gains, response = capture_exposure_gains(capture), capture_response(capture)  # cut as the capture cut them: at one exposure
        for f in posed:
            if capture.frames[f].mask_status != "ok" or f in unreadable_images:
                continue
            if _prepared_readable(capture, f):
                continue
            if not repair:
                report.unrepairable.append(f"{f}: prepared crop missing or damaged")
                continue
            try:
                capture.write_prepared(prepare_view(f, exposure_matched_image(capture, f, gains, response)[:, :, :3], capture.read_mask(f),
                                                   capture.cameras[f], crop))
                report.repaired.append(f"{f}: prepared crop cut again")
            except EmptyMaskError:
                capture.frames[f].mask_status = "empty"

    for entry in capture.updates:
        if not (capture.root / entry["state"]).is_file():
            report.unrepairable.append(f"step {entry['update']} of the reconstruction history: {entry['state']} is missing; "
                                       f"step back before it (`lirm reconstruct --after {entry['update'] - 1}`) and run it again")
    if not report.clean:
        capture.log("check", repaired=report.repaired, unrepairable=report.unrepairable)
        capture.save()
    return report


def _crop_config(capture: Capture) -> CropConfig:
    saved = capture.settings.get("config", {}).get("crop", {})
    return CropConfig(**{k: v for k, v in saved.items() if k in CropConfig.__dataclass_fields__})


def _image_readable(capture: Capture, frame_id: str) -> bool:
    path = capture.image_path(frame_id)
    if not path.is_file() or path.stat().st_size == 0:
        return False
    try:
        capture.read_image(frame_id)
    except Exception:  # the reason goes in the report's sentence
        return False
    return True


def _prepared_readable(capture: Capture, frame_id: str) -> bool:
    if not capture.prepared_path(frame_id).is_file():
        return False
    try:
        return capture.read_prepared(frame_id) is not None
    except Exception:  # a truncated or foreign file: cut it again
        return False


def _remake_masks(capture: Capture, frames: list[str]) -> dict[str, np.ndarray]:
    """Masks for `frames` made the way they were first made, where that can be done again."""
    made: dict[str, np.ndarray] = {}
    by_source: dict[str, list[str]] = {}
    for f in frames:
        by_source.setdefault(capture.frames[f].mask_source or "auto", []).append(f)
    for f in by_source.get("alpha", []):
        image = capture.read_image(f)
        if image.shape[2] == 4:
            made[f] = mask_from_alpha(image)
    user = by_source.get("user", [])
    folder = capture.settings.get("config", {}).get("masks")
    if user and folder and Path(folder).is_dir():
        names = {f: capture.frames[f].record.original.name for f in user}
        sizes = {f: (capture.cameras[f].width, capture.cameras[f].height) for f in user}
        masks, _ = load_user_masks(folder, names, sizes=sizes)
        made.update(masks)
    auto = by_source.get("auto", [])
    if auto:
        made.update(_automatic(capture, auto))
    return made


def _automatic(capture: Capture, frames: list[str]) -> dict[str, np.ndarray]:
    from .auto_mask import AutoMaskConfig, automatic_masks

    posed = sorted(capture.cameras)
    rgb = {f: capture.read_image(f)[:, :, :3] for f in posed}
    radius = capture.settings.get("config", {}).get("normalize", {}).get("target_radius", 1.0)
    is_object = None
    if capture.normalization is not None and len(capture.points):
        is_object = capture.normalization.object_point_mask(capture.points, radius)
    masks = automatic_masks(rgb, {f: capture.cameras[f] for f in posed}, capture.points, radius=radius,
                            config=AutoMaskConfig(), point_is_object=is_object,
                            support_plane=None if capture.normalization is None else capture.normalization.plane,
                            observations=capture.observations or None)
    return {f: masks[f] for f in frames if f in masks}
