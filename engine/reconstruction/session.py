"""`lirm reconstruct`: progressive LIRM updates on a prepared capture, with pictures after each.

The capture's prepared views are split, in frame order, into sets of `views_per_update`; each set
is one update of the reconstruction state (the paper's progressive scheme). After every update the
state is decoded and volume-rendered from novel orbit views (colour, albedo, roughness, metallic,
normal, opacity) and saved, so the app can show and step back through the history. capture.json's
`updates` records which frames went into which update.

Layout under the capture:
    reconstruction/update_01/state.safetensors   the plane and NDE tokens after that update
    reconstruction/update_01/view_00_colour.png  ... one PNG per novel view and channel
    reconstruction/summary.json                  per update: frames, seconds, peak memory, weights
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_json
from lirm.engine.io.images import to_uint8, write_png
from lirm.engine.model.occupancy_grid import OccupancyConfig, OccupancyGrid
from lirm.engine.model.pretrained import ModelSource
from lirm.engine.model.state_file import save_state
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera

from .novel_views import novel_view_cameras
from .view_batch import view_batch

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class ReconstructConfig:
    views_per_update: int = 4
    updates: int | None = None  # None: as many as the prepared views allow
    novel_views: int = 4
    render_size: int = 128
    render: VolumeRenderConfig = field(default_factory=lambda: VolumeRenderConfig(samples_per_ray=96))
    occupancy: OccupancyConfig = field(default_factory=lambda: OccupancyConfig(resolution=128))


@dataclass
class UpdateRecord:
    update: int
    frames: list[str]
    seconds: float
    render_seconds: float
    occupied_fraction: float
    skipped_samples: float
    out_dir: str


@dataclass
class ReconstructResult:
    out_dir: Path
    updates: list[UpdateRecord]
    trained: bool


def update_sets(frame_ids: list[str], views_per_update: int, updates: int | None) -> list[list[str]]:
    if views_per_update < 1:
        raise LirmUserError(f"--views-per-update must be at least 1, got {views_per_update}")
    sets = [frame_ids[i:i + views_per_update] for i in range(0, len(frame_ids), views_per_update)]
    return sets if updates is None else sets[:updates]


def run_reconstruction(capture_dir: str | Path, source: ModelSource, config: ReconstructConfig = ReconstructConfig(),
                       progress: Progress | None = None, cancel: Callable[[], bool] | None = None) -> ReconstructResult:
    capture = Capture.open(capture_dir)
    views = {fid: capture.read_prepared(fid) for fid in sorted(capture.cameras)}
    views = {fid: v for fid, v in views.items() if v is not None}
    if not views:
        raise LirmUserError(f"{capture.root} has no prepared views: run `lirm capture` on it first (or --resume it)")
    sets = update_sets(list(views), config.views_per_update, config.updates)
    model = source.model
    device = next(model.parameters()).device
    cameras = novel_view_cameras(list(capture.cameras.values()), config.novel_views, config.render_size)
    out_dir = capture.root / "reconstruction"
    records: list[UpdateRecord] = []
    state = model.initial_state(1)
    capture.updates = []
    for number, frames in enumerate(sets, start=1):
        if cancel is not None and cancel():
            break
        if progress:
            progress("update", number - 1, len(sets))
        batch = view_batch([views[f] for f in frames], model.config.image_size, device)
        start = time.perf_counter()
        with torch.inference_mode():
            state = model.update(state, batch)
            field = model.decode(state)
        seconds = time.perf_counter() - start
        update_dir = out_dir / f"update_{number:02d}"
        save_state(state, update_dir / "state.safetensors")
        start = time.perf_counter()
        with torch.inference_mode():
            grid = OccupancyGrid.build(field, model.config.radius, config.render.beta,
                                       2.0 * model.config.radius / config.render.samples_per_ray, config.occupancy)
            skipped = []
            for k, camera in enumerate(cameras):
                images = render_camera(field, camera, config.render, grid, device)
                _write_maps(update_dir, k, images.maps)
                skipped.append(images.stats.skipped_fraction)
        record = UpdateRecord(number, frames, seconds, time.perf_counter() - start, grid.occupied_fraction,
                              float(np.mean(skipped)), str(update_dir.relative_to(capture.root)))
        records.append(record)
        capture.updates.append({"update": number, "frames": frames, "seconds": round(seconds, 3),
                                "weights": source.description, "trained": source.trained, "state": f"{record.out_dir}/state.safetensors"})
        capture.log("reconstruct", update=number, frames=frames, weights=source.description)
        capture.save()
        atomic_write_json(out_dir / "summary.json", {
            "weights": source.description, "trained": source.trained, "warning": source.warning,
            "preset": model.config.name, "config": asdict(config), "updates": [asdict(r) for r in records],
        })
        if progress:
            progress("update", number, len(sets))
    return ReconstructResult(out_dir, records, source.trained)


def _write_maps(folder: Path, index: int, maps: dict[str, np.ndarray]) -> None:
    """sRGB-ish PNGs: colour as rendered, albedo gamma-encoded (it is linear), scalar maps as grey,
    normals as 0.5 n + 0.5 on the covered pixels."""
    opacity = maps["opacity"][..., None]
    pictures = {
        "colour": maps["colour"],
        "albedo": np.clip(maps["albedo"], 0, 1) ** (1 / 2.2) * opacity + (1 - opacity),
        "roughness": maps["roughness"],
        "metallic": maps["metallic"],
        "normal": (0.5 * maps["normal"] + 0.5) * opacity,
        "opacity": maps["opacity"],
    }
    for name, image in pictures.items():
        write_png(folder / f"view_{index:02d}_{name}.png", to_uint8(image))
