"""A user's correction of one view's mask, carried to the other views, and its undo.

The correction goes through the masks' visual hull to the other views (`propagate_mask_fix`: masks
only lose regions the corrected view rules out). Guards, because a careless correction can ruin a
capture: an empty or near-empty correction is refused; a propagated change that would take more
than half of another view's mask is not applied (the view keeps its mask, and the report names it);
every mask and prepared crop that is replaced is kept under `masks/replaced/<time>/`, so that
`undo_mask_fix` can put the last correction back. A view whose mask is no longer usable loses its
prepared crop too (kept in the same place), so prepared/ never contradicts masks/.
"""

from __future__ import annotations

import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_json

from .capture_folder import Capture
from .crop import CropConfig, prepare_view
from .exposure_match import capture_exposure_gains, capture_response, exposure_matched_image
from .masks import check_mask, propagate_mask_fix

MIN_CORRECTION_FRACTION = 0.002  # of the image: below this a "corrected" mask has no object in it
MAX_PROPAGATED_LOSS = 0.5  # a propagated change may take at most this share of another view's mask
REPLACED_DIR = "masks/replaced"


@dataclass
class MaskFixResult:
    fixed: str
    changed: list[str] = field(default_factory=list)  # other views whose masks changed
    withheld: dict[str, float] = field(default_factory=dict)  # views not changed: the share they would have lost
    backup: Path | None = None


def fix_mask(root: str | Path, frame_id: str, mask: np.ndarray, radius: float, crop: CropConfig = CropConfig()) -> MaskFixResult:
    capture = Capture.open(root)
    if frame_id not in capture.cameras:
        raise LirmUserError(f"frame {frame_id} is not posed in {root}; posed frames: {', '.join(sorted(capture.cameras))}")
    camera = capture.cameras[frame_id]
    mask = np.asarray(mask)
    if mask.shape != (camera.height, camera.width):
        raise LirmUserError(f"the corrected mask is {mask.shape[1]}x{mask.shape[0]} but frame {frame_id} is "
                            f"{camera.width}x{camera.height}; draw it on the capture's working image")
    mask = np.where(mask > 127, 255, 0).astype(np.uint8)
    share = float((mask > 0).mean())
    if share < MIN_CORRECTION_FRACTION:
        raise LirmUserError(f"the corrected mask for {frame_id} is {'empty' if share == 0 else 'nearly empty'} "
                            f"({share:.2%} of the image): paint the object white (255) on black; nothing was changed. "
                            f"To leave a view out, delete its photo and run `lirm capture --resume`")
    masks = {f: m for f in capture.cameras if (m := capture.read_mask(f)) is not None}
    new_masks, changed = propagate_mask_fix(frame_id, mask, capture.cameras, masks, radius=radius)
    result = MaskFixResult(frame_id)
    for f in changed:
        if f == frame_id:
            continue
        before = np.count_nonzero(masks[f] > 127)
        after = np.count_nonzero(new_masks[f] > 127)
        lost = 1.0 - after / before if before else 0.0
        if lost > MAX_PROPAGATED_LOSS:
            result.withheld[f] = lost
        else:
            result.changed.append(f)
    touched = [frame_id] + result.changed
    result.backup = _back_up(capture, touched, {"action": "fix mask", "frame": frame_id, "withheld": result.withheld})
    capture.write_mask(frame_id, mask, source="fixed", status=check_mask(mask) or "ok")
    for f in result.changed:
        capture.write_mask(f, new_masks[f], source="fixed", status=check_mask(new_masks[f]) or "ok")
    _recrop(capture, touched, crop)
    capture.log("fix mask", frame=frame_id, propagated_to=result.changed,
                withheld={f: round(v, 3) for f, v in result.withheld.items()},
                backup=str(result.backup.relative_to(capture.root)))
    capture.save()
    return result


def undo_mask_fix(root: str | Path, crop: CropConfig = CropConfig()) -> list[str]:
    """Put back the masks (and crops) the last correction replaced; returns the frames restored."""
    capture = Capture.open(root)
    folder = capture.root / REPLACED_DIR
    backups = sorted(p for p in folder.iterdir() if (p / "replaced.json").is_file() and not p.name.endswith(".undone")) \
        if folder.is_dir() else []
    if not backups:
        raise LirmUserError(f"{capture.root}: no mask correction to undo (nothing under {REPLACED_DIR}/)")
    last = backups[-1]
    info = json.loads((last / "replaced.json").read_text(encoding="utf-8"))
    restored = []
    for f, status in info["frames"].items():
        if (last / f"{f}.png").is_file():
            shutil.copy2(last / f"{f}.png", capture.mask_path(f))
            capture.frames[f].mask_status = status["mask_status"]
            capture.frames[f].mask_source = status["mask_source"]
            restored.append(f)
            if (last / f"{f}.npz").is_file():  # the crop as it was, byte for byte
                shutil.copy2(last / f"{f}.npz", capture.prepared_path(f))
            else:
                _recrop(capture, [f], crop)
    shutil.move(str(last), str(last.with_name(last.name + ".undone")))
    capture.log("undo fix mask", restored=restored, backup=str(last.relative_to(capture.root)))
    capture.save()
    return restored


def _back_up(capture: Capture, frames: list[str], what: dict) -> Path:
    folder = capture.root / REPLACED_DIR / time.strftime("%Y%m%d-%H%M%S")
    suffix = 1
    while folder.exists():
        suffix += 1
        folder = folder.with_name(f"{time.strftime('%Y%m%d-%H%M%S')}-{suffix}")
    folder.mkdir(parents=True)
    statuses = {}
    for f in frames:
        if capture.mask_path(f).is_file():
            shutil.copy2(capture.mask_path(f), folder / f"{f}.png")
        if capture.prepared_path(f).is_file():
            shutil.copy2(capture.prepared_path(f), folder / f"{f}.npz")
        statuses[f] = {"mask_status": capture.frames[f].mask_status, "mask_source": capture.frames[f].mask_source}
    atomic_write_json(folder / "replaced.json", {**what, "frames": statuses})
    return folder


def _recrop(capture: Capture, frames: list[str], crop: CropConfig) -> None:
    """Prepared crops follow the masks: re-cut where the mask is usable, removed where it is not."""
    gains, response = capture_exposure_gains(capture), capture_response(capture)  # at one exposure, as cut
    for f in frames:
        mask = capture.read_mask(f)
        if mask is not None and capture.frames[f].mask_status == "ok":
            capture.write_prepared(prepare_view(f, exposure_matched_image(capture, f, gains, response)[:, :, :3], mask, capture.cameras[f], crop))
        else:
            capture.prepared_path(f).unlink(missing_ok=True)
