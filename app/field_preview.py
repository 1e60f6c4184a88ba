"""The viewport's "field" channel: the raw radiance field of the update being looked at, volume-
rendered by the LIRM renderer (torch) from the viewport's camera, in a worker thread so the window
never waits. On a CPU it is a small picture (96 px on the long side by default), enlarged.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np

from lirm.engine.cameras import Camera

# After rendering a running refinement's live field, the preview rests this many times as long as the
# render took before the next one: the job it shows keeps at least 2/3 of a core (README, "The app").
LIVE_REST = 2.0


def camera_in_capture_frame(camera: Camera, world_from_capture: np.ndarray) -> Camera:
    """The viewport camera (world = exported frame) in the capture's normalised frame, where the field
    lives. world_from_capture is a uniform scale plus a translation, so the rotation is unchanged."""
    scale = float(np.cbrt(np.linalg.det(world_from_capture[:3, :3])))
    c2w = np.array(camera.c2w, np.float64)
    c2w[:3, 3] = (c2w[:3, 3] - world_from_capture[:3, 3]) / scale
    return camera.with_pose(c2w)


class FieldPreview:
    def __init__(self, size: int = 96, samples_per_ray: int = 64):
        self.size = size
        self.samples_per_ray = samples_per_ray
        self._lock = threading.Lock()
        self._field_key = None
        self._field = None
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._wanted = None  # the latest request: (key, camera)
        self.image: np.ndarray | None = None  # (H, W, 3) float colour of the last finished render
        self.image_key = None  # which request it answers
        self.error: str | None = None

    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def close(self, timeout: float = 60.0) -> None:
        """Drop what is asked and wait for the render under way (the window is closing: a torch thread
        still running when the interpreter exits aborts it)."""
        with self._lock:
            self._wanted = None
        self._closing.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def request(self, capture_dir: Path, update: int | Path, checkpoint, camera: Camera, world_from_capture: np.ndarray) -> None:
        """Render the field of `update` (a step of the history, or a state file such as a running
        refinement's live one) from `camera` (world frame) when the worker is free; the newest request
        wins, older ones are dropped."""
        scale = self.size / max(camera.width, camera.height)
        small = camera_in_capture_frame(camera.scaled(scale), world_from_capture)
        if isinstance(update, Path):  # a file that changes under the same name: its time is part of the key
            update = (update, update.stat().st_mtime_ns if update.exists() else 0)
        key = (str(capture_dir), update, tuple(np.round(small.c2w, 6).ravel()), small.width, small.height)
        with self._lock:
            self._wanted = (key, capture_dir, update, checkpoint, small)
        if not self.busy():
            self._thread = threading.Thread(target=self._work, daemon=True, name="field-preview")
            self._thread.start()

    def _work(self) -> None:
        import torch

        # One thread: the preview is small, and while a refinement runs it shares the machine with the
        # job it shows; with both processes' thread pools on 2 cores the refinement took 14 x fewer steps
        # than alone (README, "The app").
        torch.set_num_threads(1)

        from lirm.engine.model.occupancy_grid import OccupancyConfig
        from lirm.engine.model.volume_renderer import VolumeRenderConfig, fitted_render, render_camera

        while True:
            with self._lock:
                wanted, self._wanted = self._wanted, None
            if wanted is None:
                return
            key, capture_dir, update, checkpoint, camera = wanted
            started = time.perf_counter()
            try:
                field = self._decoded(capture_dir, update, checkpoint)
                with torch.inference_mode():  # a preview: the sharp density at its own samples (dense=False)
                    config, grid = fitted_render(field, VolumeRenderConfig(samples_per_ray=self.samples_per_ray,
                                                                           numerical_normals=False),
                                                 OccupancyConfig(resolution=64), dense=False)
                    out = render_camera(field, camera, config, grid)
                self.image, self.image_key, self.error = np.clip(out["colour"], 0, 1), key, None
            except Exception as err:  # shown in the viewport, never raised into the window
                self.error = f"cannot render the field: {err}"
            if isinstance(update, tuple) and self._closing.wait(LIVE_REST * (time.perf_counter() - started)):
                return  # (a live field: rest before the next; the window is closing)

    def _decoded(self, capture_dir: Path, update: int, checkpoint):
        if self._field_key == (str(capture_dir), update):
            return self._field
        from lirm.engine.capture.capture_folder import Capture
        from lirm.engine.export.capture_export import latest_state_path, reconstruction_model
        from lirm.engine.model.field_state import load_field

        if isinstance(update, tuple):  # (state file, its modification time)
            self._field = load_field(update[0])  # a refined field: no model needed
            self._field_key = (str(capture_dir), update)
            return self._field
        capture = Capture.open(capture_dir)
        model = reconstruction_model(capture, checkpoint).model
        self._field = load_field(latest_state_path(capture, update), model)  # an update's state or a refined one
        self._field_key = (str(capture_dir), update)
        return self._field
