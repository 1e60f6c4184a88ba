"""`lirm bench app-refine`: how much of a refinement the app leaves to it. The same refinement job
(the arguments the app's Refine button passes) runs for the same seconds twice on copies of a
capture: alone, then started in a real window (a scripted session: open, Refine, wait, quit) that
draws its progress and previews the live field meanwhile. On 2 cores the window and the job share
the machine; the steps each run reached say what the window costs the fit (README, "The app")."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from lirm.engine.errors import LirmUserError

from .app_idle_bench import window_display


@dataclass
class AppRefineFigures:
    capture: str
    seconds: float
    alone_steps: int
    in_app_steps: int
    alone_wall: float  # the whole job: start-up, starting field, fit, saving
    in_app_wall: float  # the app's session: start, open, the job, quit

    @property
    def share(self) -> float:
        return self.in_app_steps / max(self.alone_steps, 1)

    def report(self) -> str:
        return (f"refinement of {self.capture} for {self.seconds:g} s: alone {self.alone_steps} steps "
                f"(the job {self.alone_wall:.0f} s); in the app {self.in_app_steps} steps ({100 * self.share:.0f}% of alone; "
                f"the session {self.in_app_wall:.0f} s)")


def refine_job_args(capture: Path, seconds: float) -> list[str]:
    """The refinement as the app's Refine button starts it (app/actions.py, run_refine), with materials on."""
    return ["refine", str(capture), "--minutes", f"{seconds / 60.0:g}", "--novel-views", "1", "--render-size", "64",
            "--grid-resolution", "64", "--live", str(capture / "app" / "refine_live.safetensors"), "--live-every", "4",
            "--materials"]


def _steps(capture: Path, update: int) -> int:
    path = capture / "reconstruction" / f"update_{update:02d}" / "refine.json"
    if not path.is_file():
        raise LirmUserError(f"the refinement left no {path.relative_to(capture)}: see the log above")
    return int(json.loads(path.read_text())["steps"])


def _next_update(capture: Path) -> int:
    return len(json.loads((capture / "capture.json").read_text()).get("updates", [])) + 1


def measure_app_refine(capture: Path, seconds: float = 30.0, timeout: float = 900.0) -> AppRefineFigures:
    """Both runs on copies of `capture` (the user's folder is only read)."""
    with tempfile.TemporaryDirectory(prefix="lirm-app-refine-") as tmp:
        root = Path(tmp)
        alone, in_app = root / "alone" / "capture", root / "app" / "capture"
        for copy in (alone, in_app):
            shutil.copytree(capture, copy)
        update = _next_update(alone)
        (alone / "app").mkdir(exist_ok=True)
        start = time.monotonic()
        job = subprocess.run([sys.executable, "-m", "lirm.engine.cli"] + refine_job_args(alone, seconds),
                             capture_output=True, text=True, timeout=timeout)
        alone_wall = time.monotonic() - start
        if job.returncode != 0:
            raise LirmUserError(f"the refinement alone failed: {job.stderr.strip()[-800:]}")
        script = {"steps": [{"frames": 2}, {"action": "open_capture", "args": [str(in_app)]},
                            {"action": "run_refine", "args": [seconds / 60.0]}, {"wait": "jobs", "timeout": timeout},
                            {"quit": True}], "out": str(root / "app" / "out")}
        (root / "app" / "script.json").write_text(json.dumps(script))
        with window_display(dict(os.environ, XDG_CONFIG_HOME=str(root / "app" / "config"))) as env:
            start = time.monotonic()
            session = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "app", "--new", "--script", str(root / "app" / "script.json")],
                                     env=env, cwd=root / "app", capture_output=True, text=True, timeout=timeout)
            in_app_wall = time.monotonic() - start
        if session.returncode != 0:
            raise LirmUserError(f"the app's session failed: {session.stdout.strip()[-800:]}")
        return AppRefineFigures(str(capture), seconds, _steps(alone, update), _steps(in_app, update), alone_wall, in_app_wall)
