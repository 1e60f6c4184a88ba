"""Scripted sessions: a JSON list of steps run between frames of the real window, through the same
action layer the buttons use. The GUI tests drive the app this way (and with real clicks); a
script also records a reproducible session for a bug report.

Steps (one object each):
    {"action": "open_capture", "args": ["path"]}      any AppActions method with its arguments
    {"wait": "jobs", "timeout": 600}                  until no job runs (their results are applied)
    {"frames": 5}                                     let the window draw a few frames
    {"screenshot": "name"}                            the whole window, as <out>/name.png
    {"orbit": [dx, dy], "frames": 30}                 orbit the viewport every frame (frame-time figures)
    {"zoom": -6}                                      wheel steps on the viewport (negative: out)
    {"report_widgets": true}                          write where the named buttons are (for xdotool clicks)
    {"hover": "run_update", "frames": 8}              move the mouse pointer onto a named widget (its tooltip shows)
    {"wait_updates": 3, "timeout": 300}               until the capture has this many updates (after a real click)
    {"wait_file": "path", "timeout": 120}             until that file exists (e.g. a refinement's live state)
    {"wait_field": true, "timeout": 180}              until the field channel's picture is rendered and shown
    {"close_window": true}                            what the window's close button does (asks if work runs)
    {"quit": true}
Results (screenshots, frame times, timings, errors, messages, what the viewport shows) go to
<out>/script_result.json.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np


class ScriptRunner:
    def __init__(self, app, path: Path):
        self.app = app
        self.path = Path(path)
        data = json.loads(self.path.read_text(encoding="utf-8"))
        self.steps = data["steps"] if isinstance(data, dict) else data
        self.out = Path(data.get("out", self.path.parent)) if isinstance(data, dict) else self.path.parent
        self.out.mkdir(parents=True, exist_ok=True)
        self.index = 0
        self.waiting_since: float | None = None
        self.frames_left = 0
        self.pending_screenshot: str | None = None
        self.result = {"screenshots": {}, "steps": [], "frame_seconds": [], "errors": []}
        self._last_frame: float | None = None
        self._orbit: tuple[float, float] | None = None

    def _record(self, text: str) -> None:
        self.result["steps"].append({"t": round(time.perf_counter() - self.app.started, 3), "step": text})
        self._save()

    def _save(self) -> None:
        self.result["messages"] = [{"level": m.level, "text": m.text} for m in self.app.state.messages]
        self.result["first_frame_seconds"] = self.app.first_frame_seconds
        viewport = self.app.viewport
        self.result["viewport"] = {"channel": self.app.state.choices.view.channel, "environment_listed": self.app.state.choices.view.environment,
                                   "environment_lit": None if viewport is None else viewport.environment_key,
                                   "tonemapper": None if viewport is None else viewport.tonemapper,
                                   "scale_bar": next((p.scale_label for p in self.app.panels if hasattr(p, "scale_label")), "")}
        (self.out / "script_result.json").write_text(json.dumps(self.result, indent=1))

    def step(self) -> None:
        """Called before each frame."""
        if self.frames_left > 0:
            self.frames_left -= 1
            if self._orbit is not None and self.app.viewport is not None:
                self.app.viewport.orbit.orbit(*self._orbit)
                self.app.viewport.dirty = True
            return
        self._orbit = None
        if self.pending_screenshot is not None:
            return
        if self.index >= len(self.steps):
            return
        step = self.steps[self.index]
        if "wait" in step:
            self.waiting_since = self.waiting_since or time.monotonic()
            if self.app.jobs.running() and time.monotonic() - self.waiting_since < float(step.get("timeout", 600)):
                return
            if self.app.jobs.running():
                self.result["errors"].append(f"step {self.index}: jobs still running after {step.get('timeout', 600)} s")
            self.waiting_since = None
            self.frames_left = 2  # let the results show before the next step
        elif "wait_updates" in step:
            self.waiting_since = self.waiting_since or time.monotonic()
            enough = len(self.app.state.updates) >= int(step["wait_updates"]) and not self.app.jobs.running()
            if not enough and time.monotonic() - self.waiting_since < float(step.get("timeout", 300)):
                return
            if not enough:
                self.result["errors"].append(f"step {self.index}: {len(self.app.state.updates)} updates, not {step['wait_updates']}")
            self.waiting_since = None
            self.frames_left = 2
        elif "wait_file" in step:
            self.waiting_since = self.waiting_since or time.monotonic()
            there = Path(step["wait_file"]).exists()
            if not there and time.monotonic() - self.waiting_since < float(step.get("timeout", 120)):
                return
            if not there:
                self.result["errors"].append(f"step {self.index}: {step['wait_file']} did not appear")
            self.waiting_since = None
            self.frames_left = 2
        elif "wait_field" in step:
            self.waiting_since = self.waiting_since or time.monotonic()
            preview = self.app.field_preview
            shown = preview.image is not None and not preview.busy() and self.app.viewport is not None and not self.app.viewport.dirty
            if not shown and time.monotonic() - self.waiting_since < float(step.get("timeout", 180)):
                return
            if not shown:
                self.result["errors"].append(f"step {self.index}: the field was not rendered in time ({preview.error or 'no error'})")
            self.waiting_since = None
            self.frames_left = 3  # the frames that put the picture on screen
        elif "close_window" in step:
            import glfw

            glfw.set_window_should_close(glfw.get_current_context(), True)
            self.frames_left = 2
        elif "action" in step:
            try:
                getattr(self.app.actions, step["action"])(*step.get("args", []), **step.get("kwargs", {}))
            except Exception as err:  # the script reports, the window stays up
                self.result["errors"].append(f"step {self.index} ({step['action']}): {type(err).__name__}: {err}")
            self.frames_left = 1
        elif "orbit" in step:
            self._orbit = tuple(step["orbit"])
            self._last_frame = None
            self.result["frame_seconds"] = []
            self.frames_left = int(step.get("frames", 30))
        elif "hover" in step:
            import glfw

            rect = self.app.widget_rects.get(step["hover"])
            if rect is None:
                self.result["errors"].append(f"step {self.index}: no widget named {step['hover']!r} has been drawn")
            else:
                from imgui_bundle import imgui

                # Warp the real pointer there, and tell imgui (GLFW does not report its own warps as moves).
                # Near its left end: an item in a table column can be wider than the part of it that shows.
                x, y = rect[0] + min((rect[2] - rect[0]) / 2, 24.0), (rect[1] + rect[3]) / 2
                glfw.set_cursor_pos(glfw.get_current_context(), x, y)
                imgui.get_io().add_mouse_pos_event(x, y)
            self.frames_left = int(step.get("frames", 8))
        elif "zoom" in step:
            self.app.viewport.orbit.zoom(float(step["zoom"]))
            self.app.viewport.dirty = True
            self.frames_left = 1
        elif "frames" in step:
            self.frames_left = int(step["frames"])
        elif "screenshot" in step:
            self.pending_screenshot = step["screenshot"]
            self.frames_left = 2  # the frame after the change, fully drawn
        elif "report_widgets" in step:
            self._report_widgets()
        elif step.get("quit"):
            from imgui_bundle import hello_imgui

            self._save()
            hello_imgui.get_runner_params().app_shall_exit = True
        self._record(json.dumps(step))
        self.index += 1

    def before_swap(self) -> None:
        """The frame is drawn but not yet shown: the moment to read the window's pixels."""
        if self.pending_screenshot is not None and self.frames_left == 0:
            self._screenshot(self.pending_screenshot)
            self.pending_screenshot = None

    def after_frame(self) -> None:
        now = time.perf_counter()
        if self._orbit is not None and self._last_frame is not None:
            self.result["frame_seconds"].append(now - self._last_frame)
        self._last_frame = now

    def _screenshot(self, name: str) -> None:
        import cv2

        screen = self.app.ctx.screen
        width, height = screen.viewport[2], screen.viewport[3]
        image = np.frombuffer(screen.read(viewport=(0, 0, width, height), components=3), np.uint8).reshape(height, width, 3)[::-1]
        path = self.out / f"{name}.png"
        cv2.imwrite(str(path), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        self.result["screenshots"][name] = str(path)
        self._save()

    def _report_widgets(self) -> None:
        """Where the named buttons are (window pixels), and the window's own title for xdotool."""
        self.result["widgets"] = dict(self.app.widget_rects)
        self.result["window_title"] = "LIRM Studio"
        self._save()
