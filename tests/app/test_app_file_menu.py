"""File actions in the window (issue 21, case 4): the File menu (opened with a real click), a new
project from photos while another capture is open (a new capture, not an addition to the open one),
adding photos that are all there already (said so), and Recent listing both captures. Screenshots
are left in the test's folder (out/) to look at."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

pytestmark = [pytest.mark.display, pytest.mark.slow]


def test_new_project_add_photos_and_recent_from_the_file_menu(lego_capture, shared_data, tmp_path, x_display):
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed (`make setup` installs it)")
    capture = tmp_path / "lego"
    shutil.copytree(lego_capture, capture)
    photos = tmp_path / "fox"
    photos.mkdir()
    for p in sorted((shared_data / "real_instantngp_fox" / "images").glob("*.jpg"))[:8]:
        shutil.copy(p, photos / p.name)
    whole = (photos / "0008.jpg").read_bytes()
    (photos / "broken.jpg").write_bytes(whole[: len(whole) // 2])  # a copy that did not finish
    (photos / "notes.txt").write_text("shot at noon\n")  # a side file: not worth a warning
    clicked, helped = tmp_path / "clicked", tmp_path / "helped"
    script = {"out": str(tmp_path / "out"), "steps": [
        {"frames": 2}, {"action": "open_capture", "args": [str(capture)]}, {"frames": 2},
        {"report_widgets": True},
        {"wait_file": str(clicked), "timeout": 120}, {"frames": 3}, {"screenshot": "file_menu"},
        {"wait_file": str(helped), "timeout": 120}, {"frames": 3}, {"screenshot": "help"},
        {"action": "new_project", "args": [str(photos)]}, {"wait": "jobs", "timeout": 500}, {"screenshot": "new_project"},
        {"action": "add_photos", "args": [str(photos)]}, {"wait": "jobs", "timeout": 300},
        {"quit": True}]}
    (tmp_path / "script.json").write_text(json.dumps(script))
    env = dict(os.environ, DISPLAY=x_display, XDG_CONFIG_HOME=str(tmp_path / "config"))
    proc = subprocess.Popen([sys.executable, "-m", "lirm.engine.cli", "app", "--new", "--script", str(tmp_path / "script.json")],
                            env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    result_path = tmp_path / "out" / "script_result.json"
    try:
        deadline = time.time() + 120
        while not result_path.is_file() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.5)  # the widgets are reported once the capture is open
        window = subprocess.run(["xdotool", "search", "--name", "LIRM Studio"], env=env, capture_output=True, text=True).stdout.split()
        assert window, "the app's window is not on the display"
        subprocess.run(["xdotool", "mousemove", "--window", window[0], "22", "9", "click", "1"], env=env, check=True)
        time.sleep(1.5)
        clicked.write_text("")
        # The keys below must come after the menu's screenshot (a loaded machine draws a frame in seconds).
        shot = tmp_path / "out" / "file_menu.png"
        deadline = time.time() + 120
        while not shot.is_file() and time.time() < deadline and proc.poll() is None:
            time.sleep(0.3)
        time.sleep(0.5)
        # Close the menu, then F1: the viewport's help overlay (issue 21, case 7).
        subprocess.run(["xdotool", "key", "--window", window[0], "Escape"], env=env, check=True)
        time.sleep(0.5)
        subprocess.run(["xdotool", "mousemove", "--window", window[0], "680", "400", "key", "F1"], env=env, check=True)
        time.sleep(1.5)
        helped.write_text("")
        output, _ = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, output[-3000:]
    result = json.loads(result_path.read_text())
    assert result["errors"] == [], result["errors"]
    # The click opened the File menu: its items are drawn under the menu bar.
    menu = cv2.imread(result["screenshots"]["file_menu"])[20:200, :320].astype(int)
    assert menu.std() > 10
    # F1 put the controls over the viewport's top-right corner (dark box, light text).
    before, after = (cv2.imread(result["screenshots"][name])[90:260, 700:1020].astype(int) for name in ("file_menu", "help"))
    assert np.abs(before - after).mean() > 10
    # New project: a new capture beside the photos, opened, while the lego capture stays as it was.
    new = tmp_path / "fox_capture"
    assert (new / "capture.json").is_file()
    messages = [m["text"] for m in result["messages"]]
    assert any(m.startswith(f"opened {new}") for m in messages), messages
    # The import says which file it did not take and why (side files aside); the panel lists it.
    skipped = [m for m in messages if "not imported" in m]
    assert len(skipped) == 1 and skipped[0].startswith("1 file of fox not imported: broken.jpg: the file is cut short"), messages
    assert "notes.txt" not in skipped[0]
    assert len(json.loads((capture / "capture.json").read_text())["frames"]) == len(
        json.loads((lego_capture / "capture.json").read_text())["frames"])
    # Adding the same photos again says nothing was added.
    assert any("nothing new was added" in m for m in messages), messages
    # Recent: both captures, the new one first.
    recent = json.loads((tmp_path / "config" / "lirm" / "recent.json").read_text())["recent"]
    assert recent[:2] == [str(new.resolve()), str(capture.resolve())]
    shot = cv2.imread(result["screenshots"]["new_project"])
    assert shot is not None and np.asarray(shot).std() > 5
