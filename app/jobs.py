"""Long work (posing, LIRM updates, guidance, export) as `lirm` subprocesses, so the window never
waits on it: each job reports progress through the command's progress events, can be cancelled, and
survives in its own process group. Results are files in the capture folder, written atomically by
the commands themselves, so a job cut short never leaves a half-written file behind.

The runner is polled once per frame from the UI thread; a reader thread per job follows its output,
which goes to a log file (not a pipe): a job left to finish after the app quits (an export) must not
die writing to a reader that is gone, and the logs stay for the user to read.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from lirm.engine import progress_events
from lirm.engine.io.user_cache import user_cache_folder

CANCEL_GRACE_SECONDS = 5.0  # after Ctrl-C, how long a job may take to stop before it is killed


@dataclass
class Job:
    kind: str  # "capture", "update", "suggest", "export", ...
    title: str  # shown in the window
    argv: list[str]
    on_done: Callable[["Job"], None] | None = None
    detach_on_exit: bool = False  # keep running when the app quits (exports: the file still arrives)
    cancel_grace: float = CANCEL_GRACE_SECONDS  # seconds after Ctrl-C before it is killed
    started: float = field(default_factory=time.monotonic)
    stage: str = "starting"
    done: int = 0
    total: int = 0
    state: str = "running"  # running | finished | failed | cancelled
    returncode: int | None = None
    finished_at: float | None = None
    output: list[str] = field(default_factory=list)  # stderr and stdout lines, newest last
    process: subprocess.Popen | None = field(default=None, repr=False)
    cancel_requested: float | None = None
    log_path: Path | None = None
    peak_memory_mb: float | None = None  # the job's peak resident memory, from the kernel at exit

    @property
    def fraction(self) -> float:
        return self.done / self.total if self.total else 0.0

    @property
    def seconds(self) -> float:
        return (self.finished_at or time.monotonic()) - self.started

    def error_text(self) -> str:
        """What went wrong, as the command said it (its last error lines)."""
        lines = [line for line in self.output if line.startswith(("error:", "ERROR", "Traceback")) or "Error" in line]
        return "\n".join(lines[-3:] or self.output[-3:])


def _has_exited(process: subprocess.Popen) -> bool:
    """Whether the child has ended, without reaping it (wait4 collects its rusage afterwards)."""
    try:
        return os.waitid(os.P_PID, process.pid, os.WEXITED | os.WNOHANG | os.WNOWAIT) is not None
    except ChildProcessError:
        return True


def _wait_with_usage(process: subprocess.Popen) -> tuple[int, float | None]:
    """The exit code and peak memory (MB) of a finished child, reaped with wait4 for its rusage."""
    try:
        _, status, usage = os.wait4(process.pid, 0)
    except ChildProcessError:  # already reaped (e.g. by poll): the code is known, the usage is not
        return process.wait(), None
    process.returncode = os.waitstatus_to_exitcode(status)
    return process.returncode, usage.ru_maxrss / 1024.0  # Linux reports kilobytes


class JobRunner:
    def __init__(self, python: str = sys.executable, env: dict | None = None, log_dir: Path | None = None):
        self.python = python
        self.log_dir = Path(log_dir) if log_dir else user_cache_folder() / "job_logs"
        self.env = dict(os.environ if env is None else env)
        self.env[progress_events.ENV] = "1"
        self.jobs: list[Job] = []
        self._finished: list[Job] = []
        self._lock = threading.Lock()

    def start(self, kind: str, title: str, args: list[str], on_done: Callable[[Job], None] | None = None,
              detach_on_exit: bool = False, cancel_grace: float = CANCEL_GRACE_SECONDS) -> Job:
        job = Job(kind, title, [self.python, "-m", "lirm.engine.cli", *args], on_done, detach_on_exit, cancel_grace)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        job.log_path = self.log_dir / f"{time.strftime('%Y%m%d-%H%M%S')}-{kind}-{os.getpid()}-{len(self.jobs)}.log"
        with open(job.log_path, "w", encoding="utf-8") as log:
            log.write(" ".join(job.argv) + "\n")
            log.flush()
            job.process = subprocess.Popen(job.argv, stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                           env=self.env, start_new_session=True)
        self.jobs.append(job)
        threading.Thread(target=self._follow, args=(job,), daemon=True, name=f"job-{kind}").start()
        return job

    def _follow(self, job: Job) -> None:
        """Read the job's log as it grows until the process has ended and the log is read to the end."""
        assert job.process is not None and job.log_path is not None
        pending = ""
        with open(job.log_path, encoding="utf-8", errors="replace") as log:
            log.readline()  # the command line written above
            while True:
                chunk = log.read()
                if not chunk:
                    if _has_exited(job.process):
                        chunk = log.read()
                        if not chunk:
                            break
                    else:
                        time.sleep(0.05)
                        continue
                pending += chunk
                *lines, pending = pending.replace("\r", "\n").split("\n")
                for line in lines:
                    self._take(job, line)
        if pending:
            self._take(job, pending)
        job.returncode, job.peak_memory_mb = _wait_with_usage(job.process)
        job.finished_at = time.monotonic()
        if job.cancel_requested is not None:
            job.state = "cancelled"
        else:
            job.state = "finished" if job.returncode == 0 else "failed"
        with self._lock:
            self._finished.append(job)

    @staticmethod
    def _take(job: Job, line: str) -> None:
        event = progress_events.parse(line)
        if event is not None:
            job.stage, job.done, job.total = str(event["stage"]), int(event["done"]), int(event["total"])
        elif line.strip():
            job.output.append(line.rstrip())
            del job.output[:-200]

    def running(self, kind: str | None = None) -> list[Job]:
        return [j for j in self.jobs if j.state == "running" and (kind is None or j.kind == kind)]

    def cancel(self, job: Job) -> None:
        """Ctrl-C to the job's process group (the commands stop cleanly on it), a kill if it lingers."""
        if job.state != "running" or job.process is None:
            return
        job.cancel_requested = time.monotonic()
        try:
            os.killpg(job.process.pid, signal.SIGINT)
        except ProcessLookupError:
            pass

    def poll(self) -> list[Job]:
        """Once per frame on the UI thread: escalate slow cancels, run the callbacks of finished jobs."""
        for job in self.running():
            if job.cancel_requested is not None and time.monotonic() - job.cancel_requested > job.cancel_grace:
                try:
                    os.killpg(job.process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        with self._lock:
            finished, self._finished = self._finished, []
        for job in finished:
            if job.on_done is not None:
                job.on_done(job)
        return finished

    def wait(self, timeout: float = 600.0) -> None:
        """Block until every job is done (tests and the headless flow), running the callbacks."""
        end = time.monotonic() + timeout
        while self.running() and time.monotonic() < end:
            time.sleep(0.05)
            self.poll()
        time.sleep(0.05)
        self.poll()

    def shutdown(self) -> list[Job]:
        """At exit: cancel what would be lost anyway, leave detached jobs (exports) to finish on their own.
        Returns the jobs left running."""
        left = []
        for job in self.running():
            if job.detach_on_exit:
                left.append(job)
            else:
                self.cancel(job)
        return left
