"""`lirm export CAPTURE`: the capture's latest reconstruction state, decoded by the model that made
it, exported as a .glb at the capture's real-world scale.

The normalised capture frame is +Z up with the object inside the unit sphere; the export divides
by the normalisation's scale (back to the photos' units: metres when the poses were metric) and,
stands the object on glTF's ground: its lowest point at height 0, its base centred on the vertical axis.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.errors import LirmUserError
from lirm.engine.model.pretrained import ModelSource, load_model
from lirm.engine.model.field_state import load_field

from .export_asset import ExportConfig, ExportResult, Progress, export_field


def reconstruction_model(capture: Capture, checkpoint: str | Path | None = None) -> ModelSource:
    """The model that decodes the capture's reconstruction states: `checkpoint`, else the preset the
    reconstruction recorded in its summary.json (the shipped or untrained weights of that preset)."""
    summary_path = capture.root / "reconstruction" / "summary.json"
    preset = json.loads(summary_path.read_text())["preset"] if summary_path.is_file() else None
    return load_model(checkpoint, preset)


def latest_state_path(capture: Capture, update: int | None = None) -> Path:
    """The state after `update` (1-based; default the latest)."""
    if not capture.updates:
        raise LirmUserError(f"{capture.root} has no reconstruction yet: run `lirm reconstruct {capture.root}` first")
    if update is None:
        return capture.root / capture.updates[-1]["state"]
    if not 1 <= update <= len(capture.updates):
        raise LirmUserError(f"{capture.root} has updates 1..{len(capture.updates)}, not {update}")
    return capture.root / capture.updates[update - 1]["state"]


def export_transform(capture: Capture) -> np.ndarray:
    """From the normalised frame to the exported one: real-world scale, standing on the support plane."""
    m = np.eye(4)
    if capture.normalization is None:
        return m
    scale = capture.normalization.scale
    m[:3, :3] /= scale
    plane = capture.normalization.plane
    if plane is not None and abs(float(plane[0][2])) > 0.9:  # a floor under the object (n ~ +Z)
        m[2, 3] = -float(plane[1]) / float(plane[0][2]) / scale
    return m


def standing_on_the_ground(transform: np.ndarray, vertices: np.ndarray, base_slice: float = 0.02) -> np.ndarray:
    """`transform` (normalised frame -> exported, +Z up) moved so that the object's lowest vertex is at
    height 0 and the centre of its base (the bounding box of the lowest `base_slice` of its height)
    is on the vertical axis: the asset stands on glTF's ground at the origin, whatever the support
    plane's estimate said (it sat 3.7 cm above it on the demo mug before)."""
    placed = vertices @ transform[:3, :3].T + transform[:3, 3]
    if len(placed) == 0:
        return transform
    low, high = placed[:, 2].min(), placed[:, 2].max()
    base = placed[placed[:, 2] <= low + base_slice * max(high - low, 1e-9)]
    centre = 0.5 * (base[:, :2].min(axis=0) + base[:, :2].max(axis=0))
    moved = transform.copy()
    moved[:3, 3] -= np.array([centre[0], centre[1], low])
    return moved


def in_metres(transform: np.ndarray, vertices: np.ndarray, real_size: dict | None) -> np.ndarray:
    """`transform` rescaled so that the object's stated height (its extent along up) or width (its
    largest horizontal extent) comes out in metres; unchanged without a stated size."""
    if not real_size:
        return transform
    placed = vertices @ transform[:3, :3].T + transform[:3, 3]
    if "height" in real_size:
        extent, metres = float(np.ptp(placed[:, 2])), float(real_size["height"])
    else:
        extent, metres = float(np.ptp(placed[:, :2], axis=0).max()), float(real_size["width"])
    if extent <= 0:
        return transform
    scaled = transform.copy()
    scaled[:3, :] *= metres / extent
    return scaled


def export_capture(capture_dir: str | Path, out_path: str | Path, config: ExportConfig = ExportConfig(),
                   checkpoint: str | Path | None = None, progress: Progress | None = None,
                   source: ModelSource | None = None, update: int | None = None) -> tuple[ExportResult, ModelSource]:
    """`source`: the model already loaded by the caller (else reconstruction_model's choice); `update`:
    the state after that update instead of the latest."""
    capture = Capture.open(capture_dir)
    state_path = latest_state_path(capture, update)
    source = source or reconstruction_model(capture, checkpoint)
    # An update's tokens are decoded by the model (a state of another architecture is refused there, by
    # name); a refined state holds its own field.
    field = load_field(state_path, source.model)
    transform = export_transform(capture)
    real_size = capture.settings.get("real_size")

    def placement(vertices: np.ndarray) -> np.ndarray:
        return standing_on_the_ground(in_metres(transform, vertices, real_size), vertices)

    units = "metres" if real_size else "capture units"
    return export_field(field, out_path, config, placement, progress, units=units), source
