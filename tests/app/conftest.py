"""Fixtures of the window tests: a scripted session of the real app."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest


@pytest.fixture
def scripted_session(tmp_path, x_display):
    """run(steps, timeout=600): the app on the test's display runs `steps` (app/script.py) and quits;
    returns its script_result.json after checking that it exited cleanly and the script raised no
    errors. Screenshots go to tmp_path/out."""
    def run(steps: list[dict], timeout: int = 600) -> dict:
        script = tmp_path / "script.json"
        script.write_text(json.dumps({"out": str(tmp_path / "out"), "steps": steps}))
        env = dict(os.environ, DISPLAY=x_display, XDG_CONFIG_HOME=str(tmp_path / "config"))
        proc = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "app", "--new", "--script", str(script)],
                              env=env, cwd=tmp_path, capture_output=True, text=True, timeout=timeout)
        assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
        result = json.loads((tmp_path / "out" / "script_result.json").read_text())
        assert result["errors"] == [], result["errors"]
        return result

    return run
