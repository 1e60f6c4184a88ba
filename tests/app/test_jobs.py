"""The app's background jobs: Cancel reaches the command even where SIGINT reaches nobody by default."""

from __future__ import annotations

import json
import shutil
import signal
import time

from lirm.app.jobs import JobRunner


def test_cancel_reaches_a_job_started_with_sigint_ignored(lego_capture, tmp_path):
    """A script's `cmd &` (and CI) starts the app with SIGINT ignored, which its jobs inherit; Cancel must
    still stop a refinement cleanly (its best state kept), not wait for the kill at the end of the grace."""
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        jobs = JobRunner(log_dir=tmp_path / "logs")
        job = jobs.start("refine", "refinement", ["refine", str(capture), "--minutes", "5", "--novel-views", "1",
                                                   "--render-size", "32", "--grid-resolution", "32"],
                         cancel_grace=600.0)
    finally:
        signal.signal(signal.SIGINT, previous)
    end = time.monotonic() + 300
    while not job.stage.startswith("refining: step") and job.state == "running" and time.monotonic() < end:
        time.sleep(0.2)
    assert job.state == "running", job.output[-5:]
    jobs.cancel(job)
    jobs.wait(timeout=300)
    assert job.state == "cancelled"
    assert job.returncode == 0, job.output[-5:]  # stopped by the Ctrl-C itself, not killed
    assert any("cancelled: kept the best state so far" in line for line in job.output), job.output[-5:]
    updates = json.loads((capture / "capture.json").read_text())["updates"]
    assert [u.get("kind", "update") for u in updates][-1] == "refine"
