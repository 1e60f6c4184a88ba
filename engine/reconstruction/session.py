"""`lirm reconstruct`: progressive LIRM updates on a prepared capture, with pictures after each.

The capture's prepared views are split into sets of `views_per_update`, each spread over the object
(farthest-first over viewing directions; in frame order on request); each set is one update of the
reconstruction state (the paper's progressive scheme). After every update the
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
from lirm.engine.capture.capture_lock import capture_lock
from lirm.engine.capture.history_journal import HistoryBuild
from lirm.engine.errors import LirmUserError
from lirm.engine.io.images import to_uint8, write_png
from lirm.engine.model.occupancy_grid import OccupancyConfig
from lirm.engine.model.pretrained import ModelSource
from lirm.engine.model.state_file import save_state
from lirm.engine.model.volume_renderer import VolumeRenderConfig, fitted_render, render_camera

from .novel_views import novel_view_cameras
from .view_batch import view_batch

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class ReconstructConfig:
    views_per_update: int = 4
    updates: int | None = None  # None: as many as the prepared views allow
    order: str = "spread"  # "spread": each update's views farthest-first over the object; "frames": in frame order
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


def spread_order(frame_ids: list[str], cameras: dict, already: list[str] = ()) -> list[str]:
    """The frames farthest-first over viewing directions: each next one is the view whose direction
    from the object is the farthest from every view before it (those `already` used too), starting
    from the first frame when nothing is used yet. Cut into sets, each update then sees the object
    from all round instead of from one arc of a walk-around."""
    from lirm.engine.guidance.next_views import farthest_views

    frame_ids = list(frame_ids)
    if not frame_ids:
        return []
    existing = [cameras[f] for f in already if f in cameras]
    start = [] if existing else [0]
    if not existing:
        existing = [cameras[frame_ids[0]]]
    rest = farthest_views(existing, [cameras[f] for f in frame_ids], len(frame_ids) - len(start), exclude=tuple(start))
    return [frame_ids[i] for i in start + rest]


def update_sets(frame_ids: list[str], views_per_update: int, updates: int | None, cameras: dict | None = None) -> list[list[str]]:
    """The views of each update: in sets of `views_per_update`, spread over the object (spread_order)
    when the cameras are given, else in frame order."""
    if views_per_update < 1:
        raise LirmUserError(f"--views-per-update must be at least 1, got {views_per_update}")
    if cameras is not None:
        frame_ids = spread_order(frame_ids, cameras)
    sets = [frame_ids[i:i + views_per_update] for i in range(0, len(frame_ids), views_per_update)]
    return sets if updates is None else sets[:updates]


def run_reconstruction(capture_dir: str | Path, source: ModelSource, config: ReconstructConfig = ReconstructConfig(),
                       progress: Progress | None = None, cancel: Callable[[], bool] | None = None) -> ReconstructResult:
    """All updates from scratch, the prepared views in sets of `views_per_update`, each set spread over
    the object (`config.order` "spread", the default) or in frame order ("frames").

    The new updates are built beside the earlier history and replace it only when they are done
    (`cancel` keeps the updates finished so far); an exception or a killed process leaves the
    capture as it was (engine/capture/history_journal.py)."""
    with capture_lock(capture_dir, "lirm reconstruct"):
        capture = open_checked(capture_dir)
        views = prepared_views(capture)
        cameras = {f: capture.cameras[f] for f in views} if config.order == "spread" else None
        sets = update_sets(list(views), config.views_per_update, config.updates, cameras)
        with HistoryBuild(capture) as build:
            session = _Session(capture, source, config, build)
            state = source.model.initial_state(1)
            for number, frames in enumerate(sets, start=1):
                if cancel is not None and cancel():
                    break
                if progress:
                    progress("update", number - 1, len(sets))
                state = session.apply(state, number, frames, views)
                if progress:
                    progress("update", number, len(sets))
            if session.records:
                session.commit(keep=0)
    return ReconstructResult(session.out_dir, session.records, source.trained)


def run_next_update(capture_dir: str | Path, source: ModelSource, frames: list[str], after_update: int | None = None,
                    config: ReconstructConfig = ReconstructConfig()) -> ReconstructResult:
    """One more update with the chosen frames, on top of update `after_update` (default: the latest;
    0 starts afresh). Updates after it are set aside under reconstruction/set_aside/, never deleted:
    that is stepping back in the history and going on from there. They are set aside only once the
    new update is finished."""
    from lirm.engine.model.state_file import load_state

    with capture_lock(capture_dir, "lirm reconstruct"):
        capture = open_checked(capture_dir)
        views = prepared_views(capture)
        unknown = [f for f in frames if f not in views]
        if not frames or unknown:
            raise LirmUserError(f"{capture.root}: {'no frames chosen' if not frames else 'no prepared view for ' + ', '.join(unknown)}; "
                                f"choose among: {', '.join(views)}")
        done = len(capture.updates)
        after = done if after_update is None else after_update
        if not 0 <= after <= done:
            raise LirmUserError(f"{capture.root} has {done} updates; cannot continue after update {after}")
        model = source.model
        # A refined step holds a field, not tokens: the network goes on from the last update's tokens
        # before it (a later refinement warm-starts from the refined field again, engine/refine/).
        base = last_update_entry(capture.updates[:after])
        if base is None:
            state = model.initial_state(1)
        else:
            state = load_state(capture.root / base["state"], device=str(next(model.parameters()).device))
            if state.signature != model.config.signature():
                raise LirmUserError(f"update {base['update']} of {capture.root} was made with other weights ({base.get('weights')}); "
                                    f"pass the same --checkpoint, or start afresh with --after 0")
        with HistoryBuild(capture) as build:
            session = _Session(capture, source, config, build)
            session.apply(state, after + 1, list(frames), views)
            session.commit(keep=after)
    return ReconstructResult(session.out_dir, session.records, source.trained)


def last_update_entry(entries: list[dict]) -> dict | None:
    """The last history entry made by a LIRM update (not a refinement), or None."""
    updates = [e for e in entries if e.get("kind", "update") == "update"]
    return updates[-1] if updates else None


def open_checked(capture_dir: str | Path) -> Capture:
    """The capture, after checking it against capture.json: what can be made again (crops, masks)
    is, and what cannot is named on the log, so that a damaged capture is never silently smaller."""
    import logging

    from lirm.engine.capture.capture_check import check_capture

    report = check_capture(capture_dir)
    if not report.clean:
        log = logging.getLogger("lirm")
        for line in report.lines():
            log.warning("%s: %s", capture_dir, line.strip())
    return Capture.open(capture_dir)


def prepared_views(capture: Capture) -> dict:
    views = {fid: capture.read_prepared(fid) for fid in sorted(capture.cameras)}
    views = {fid: v for fid, v in views.items() if v is not None}
    if not views:
        raise LirmUserError(f"{capture.root} has no prepared views: run `lirm capture` on it first (or --resume it)")
    return views


class _Session:
    """Builds updates of a capture's reconstruction (state, novel-view pictures) in a HistoryBuild,
    then commits them with their history entries and summary."""

    def __init__(self, capture: Capture, source: ModelSource, config: ReconstructConfig, build: HistoryBuild):
        self.capture, self.source, self.config, self.build = capture, source, config, build
        self.model = source.model
        self.device = next(self.model.parameters()).device
        self.cameras = novel_view_cameras(list(capture.cameras.values()), config.novel_views, config.render_size)
        self.out_dir = capture.root / "reconstruction"
        self.records: list[UpdateRecord] = []
        self.entries: list[dict] = []
        self.log: list[dict] = []

    def apply(self, state, number: int, frames: list[str], views: dict):
        model, config = self.model, self.config
        batch = view_batch([views[f] for f in frames], model.config.image_size, self.device)
        start = time.perf_counter()
        with torch.inference_mode():
            state = model.update(state, batch)
            field = model.decode(state)
        seconds = time.perf_counter() - start
        folder = self.build.folder(number)
        save_state(state, folder / "state.safetensors")
        start = time.perf_counter()
        occupied, skipped = write_pictures(field, self.cameras, config, folder, self.device)
        state_path = self.build.final_state_path(number)
        record = UpdateRecord(number, frames, seconds, time.perf_counter() - start, occupied, skipped,
                              str(Path(state_path).parent))
        self.records.append(record)
        self.entries.append({"update": number, "frames": frames, "seconds": round(seconds, 3),
                             "weights": self.source.description, "trained": self.source.trained, "state": state_path})
        self.log.append({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "action": "reconstruct", "update": number,
                         "frames": frames, "weights": self.source.description})
        return state

    def commit(self, keep: int) -> None:
        summary = summary_with(self.out_dir, self.source, self.config, keep, [asdict(r) for r in self.records])
        self.build.commit(keep, self.entries, summary, self.log)


def write_pictures(field, cameras: list, config: ReconstructConfig, folder: Path, device) -> tuple[float, float]:
    """Volume-render `field` from `cameras` into folder/view_KK_<channel>.png; returns the occupancy
    grid's occupied fraction and the mean share of samples it skipped."""
    with torch.inference_mode():
        render, grid = fitted_render(field, config.render, config.occupancy)
        skipped = []
        for k, camera in enumerate(cameras):
            images = render_camera(field, camera, render, grid, device)
            _write_maps(folder, k, images.maps)
            skipped.append(images.stats.skipped_fraction)
    return grid.occupied_fraction, float(np.mean(skipped)) if skipped else 0.0


def summary_with(out_dir: Path, source: ModelSource, config: ReconstructConfig, keep: int, records: list[dict]) -> dict:
    """summary.json's content: the steps up to `keep` as they were, then these records."""
    import json

    summary_path = out_dir / "summary.json"
    earlier = []
    if summary_path.is_file() and keep > 0:
        try:
            earlier = [u for u in json.loads(summary_path.read_text()).get("updates", []) if u["update"] <= keep]
        except (OSError, ValueError, KeyError):
            earlier = []  # a damaged summary is rebuilt from here on; the history itself is capture.json
    return {
        "weights": source.description, "trained": source.trained, "warning": source.warning,
        "preset": source.model.config.name, "config": asdict(config), "updates": earlier + records,
    }


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
