"""`lirm bench app-idle`: the share of a CPU core the app uses while it sits idle (issue 21's goal:
under 3%), measured from the process's own CPU time (/proc/PID/stat) over a quiet interval after
start-up, in a real window (the given $DISPLAY, or a private Xvfb)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from lirm.engine.errors import LirmUserError


@dataclass
class IdleFigures:
    settle_seconds: float
    measured_seconds: float
    cpu_seconds: float
    capture: str

    @property
    def core_share(self) -> float:
        return self.cpu_seconds / self.measured_seconds

    def report(self) -> str:
        return (f"app idle on {self.capture}: {100 * self.core_share:.1f}% of one core "
                f"({self.cpu_seconds:.2f} s of CPU in {self.measured_seconds:.0f} s, after {self.settle_seconds:.0f} s to settle); "
                f"goal: under 3%")


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process and its threads, in seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


@contextmanager
def window_display(env: dict):
    """`env` with a DISPLAY: the one given, else a private Xvfb's for the duration."""
    if env.get("DISPLAY"):
        yield env
        return
    if shutil.which("Xvfb") is None:
        raise LirmUserError("no display and no Xvfb to start one (apt-get install xvfb; `make setup` installs it)")
    read_fd, write_fd = os.pipe()
    xvfb = subprocess.Popen(["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
                            pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        display = ":" + pipe.readline().strip()
    try:
        yield dict(env, DISPLAY=display)
    finally:
        xvfb.terminate()
        xvfb.wait(timeout=10)


def measure_idle(capture: Path | None = None, settle: float = 20.0, seconds: float = 30.0,
                 command: list[str] | None = None) -> IdleFigures:
    """`command` replaces `lirm app` (e.g. another build of the app, to compare)."""
    with tempfile.TemporaryDirectory(prefix="lirm-idle-") as tmp, window_display(dict(os.environ, XDG_CONFIG_HOME=tmp)) as env:
        args = command or [sys.executable, "-m", "lirm.engine.cli", "app"] + ([str(capture)] if capture else ["--new"])
        app = subprocess.Popen(args, env=env, cwd=tmp, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            time.sleep(settle)
            if app.poll() is not None:
                raise LirmUserError(f"the app exited during start-up (code {app.returncode}); run `{' '.join(args[2:])}` to see why")
            start_cpu, start = _cpu_seconds(app.pid), time.monotonic()
            time.sleep(seconds)
            used, elapsed = _cpu_seconds(app.pid) - start_cpu, time.monotonic() - start
        finally:
            app.terminate()
            try:
                app.wait(timeout=20)
            except subprocess.TimeoutExpired:
                app.kill()
    return IdleFigures(settle, elapsed, used, str(capture) if capture else "an empty project")
