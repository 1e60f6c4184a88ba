"""`lirm export CAPTURE`: the capture's latest reconstruction state, decoded by the model that made
it, exported as a .glb at the capture's real-world scale.

The normalised capture frame is +Z up with the object inside the unit sphere; the export divides
by the normalisation's scale (back to the photos' units: metres when the poses were metric) and,
stands the object on glTF's ground: its lowest point at height 0, its base centred on the vertical axis.

A state refined with materials (`lirm refine --materials`: a lighting.hdr beside it) also brings the
photos it was fitted to and that lighting, and the export's textures are fitted to those photos
(photo_texture_fit.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.normalize import is_floor
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


def chosen_entry(capture: Capture, update: int | None = None) -> dict:
    """The history entry of the update that is exported (1-based; default the latest)."""
    if not capture.updates:
        raise LirmUserError(f"{capture.root} has no reconstruction yet: run `lirm reconstruct {capture.root}` first")
    if update is None:
        return capture.updates[-1]
    if not 1 <= update <= len(capture.updates):
        raise LirmUserError(f"{capture.root} has updates 1..{len(capture.updates)}, not {update}")
    return capture.updates[update - 1]


def texture_fit_inputs(capture: Capture, entry: dict):
    """(PhotoViews, PanoramaLighting) for fitting the export's textures: the prepared views a
    refinement with materials was fitted to and the lighting it fitted (lighting.hdr beside its
    state); None for any other state (an update, or a refinement without materials)."""
    if entry.get("kind") != "refine" or not entry.get("state"):
        return None
    lighting_file = capture.root / Path(entry["state"]).parent / "lighting.hdr"
    if not lighting_file.is_file():
        return None
    from lirm.engine.assets.environment_files import load_environment_file
    from lirm.engine.lighting.panorama_lighting import PanoramaLighting

    from .photo_texture_fit import PhotoViews

    views = [capture.read_prepared(fid) for fid in entry.get("frames", [])]
    views = [v for v in views if v is not None]
    if not views:
        return None
    environment = load_environment_file(lighting_file)
    # (refinements from before the curve was recorded were all fitted through ACES)
    lighting = PanoramaLighting.from_environment(environment, environment.radiance.shape[0],
                                                 camera_response=entry.get("camera_response", "aces"))
    photos = PhotoViews([v.camera for v in views], np.stack([v.image_masked for v in views]), np.stack([v.mask for v in views]))
    return photos, lighting


def latest_state_path(capture: Capture, update: int | None = None) -> Path:
    """The state after `update` (1-based; default the latest)."""
    return capture.root / chosen_entry(capture, update)["state"]


def export_transform(capture: Capture) -> np.ndarray:
    """From the normalised frame to the exported one: real-world scale, standing on the support plane."""
    m = np.eye(4)
    if capture.normalization is None:
        return m
    scale = capture.normalization.scale
    m[:3, :3] /= scale
    plane = capture.normalization.plane
    if is_floor(plane):
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
                   source: ModelSource | None = None, update: int | None = None,
                   should_stop=None) -> tuple[ExportResult, ModelSource]:
    """`source`: the model already loaded by the caller (else reconstruction_model's choice); `update`:
    the state after that update instead of the latest. A state refined with materials has its
    textures fitted to its photos (config.texture_fit; `should_stop` ends that fit early)."""
    capture = Capture.open(capture_dir)
    entry = chosen_entry(capture, update)
    state_path = capture.root / entry["state"]
    fit_inputs = texture_fit_inputs(capture, entry) if config.texture_fit is not None else None
    source = source or reconstruction_model(capture, checkpoint)
    # An update's tokens are decoded by the model (a state of another architecture is refused there, by
    # name); a refined state holds its own field.
    field = load_field(state_path, source.model)
    transform = export_transform(capture)
    real_size = capture.settings.get("real_size")

    def placement(vertices: np.ndarray) -> np.ndarray:
        return standing_on_the_ground(in_metres(transform, vertices, real_size), vertices)

    units = "metres" if real_size else "capture units"
    photos, lighting = fit_inputs if fit_inputs is not None else (None, None)
    return export_field(field, out_path, config, placement, progress, units=units, photos=photos, lighting=lighting,
                        should_stop=should_stop), source
