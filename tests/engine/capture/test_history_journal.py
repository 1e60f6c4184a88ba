"""The reconstruction history changes all at once or not at all (issue 20, case 1), and one writer
holds a capture at a time (case 9)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from lirm.engine.capture import history_journal
from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.capture_lock import capture_lock
from lirm.engine.capture.history_journal import HistoryBuild, finish_commit, remove_stale_builds
from lirm.engine.errors import LirmUserError


def _capture_with_steps(root, count: int) -> Capture:
    capture = Capture.create(root)
    for n in range(1, count + 1):
        folder = root / "reconstruction" / f"update_{n:02d}"
        folder.mkdir(parents=True)
        (folder / "state.safetensors").write_text(f"old {n}")
        capture.updates.append({"update": n, "frames": [str(n)], "state": f"reconstruction/update_{n:02d}/state.safetensors"})
    capture.save()
    return capture


def _build_new(build: HistoryBuild, numbers) -> list[dict]:
    entries = []
    for n in numbers:
        (build.folder(n) / "state.safetensors").write_text(f"new {n}")
        entries.append({"update": n, "frames": ["x"], "state": build.final_state_path(n)})
    return entries


def test_a_build_that_fails_leaves_the_history_as_it_was(tmp_path):
    root = tmp_path / "c"
    capture = _capture_with_steps(root, 3)
    before = (root / "capture.json").read_text()
    for error in (KeyboardInterrupt, MemoryError, RuntimeError):
        with pytest.raises(error):
            with HistoryBuild(capture) as build:
                _build_new(build, [1, 2])
                raise error()
        assert (root / "capture.json").read_text() == before
        assert [p.name for p in sorted((root / "reconstruction").iterdir())] == ["update_01", "update_02", "update_03"]
        assert (root / "reconstruction" / "update_02" / "state.safetensors").read_text() == "old 2"


def test_a_commit_replaces_later_steps_and_sets_them_aside(tmp_path):
    root = tmp_path / "c"
    capture = _capture_with_steps(root, 3)
    with HistoryBuild(capture) as build:
        entries = _build_new(build, [2])
        build.commit(1, entries, {"updates": entries}, [{"action": "reconstruct", "update": 2}])
    reopened = Capture.open(root)
    assert [e["frames"] for e in reopened.updates] == [["1"], ["x"]]
    assert (root / "reconstruction" / "update_02" / "state.safetensors").read_text() == "new 2"
    aside = {p.parent.name + "/" + p.read_text() for p in (root / "reconstruction" / "set_aside").glob("*/update_*/state.safetensors")}
    assert len(aside) == 2 and {a.split("/")[1] for a in aside} == {"old 2", "old 3"}
    assert not list((root / "reconstruction").glob(".building_*")) and not (root / "reconstruction" / ".commit.json").exists()
    assert json.loads((root / "reconstruction" / "summary.json").read_text())["updates"] == entries


@pytest.mark.parametrize("stop_after", [0, 1, 2])
def test_a_commit_killed_half_way_is_finished_when_the_capture_opens(tmp_path, monkeypatch, stop_after):
    """A kill after the journal exists (before, between or after the moves): Capture.open rolls forward, and
    rolling forward again changes nothing."""
    root = tmp_path / "c"
    capture = _capture_with_steps(root, 3)
    real_move, moves = history_journal._move_into_place, []

    def dying_move(src, dst):
        if len(moves) >= stop_after:
            raise SystemExit("killed")  # stands for SIGKILL: nothing after this line runs
        moves.append(dst)
        real_move(src, dst)

    monkeypatch.setattr(history_journal, "_move_into_place", dying_move)
    real_write = history_journal.atomic_write_json

    def dying_write(path, obj):
        if path.name == "capture.json":
            raise SystemExit("killed")
        return real_write(path, obj)

    monkeypatch.setattr(history_journal, "atomic_write_json", dying_write)
    with pytest.raises(SystemExit):
        with HistoryBuild(capture) as build:
            build.commit(0, _build_new(build, [1, 2]), None, [])
    monkeypatch.setattr(history_journal, "_move_into_place", real_move)
    monkeypatch.setattr(history_journal, "atomic_write_json", real_write)
    reopened = Capture.open(root)
    assert [e["frames"] for e in reopened.updates] == [["x"], ["x"]]
    for n in (1, 2):
        assert (root / "reconstruction" / f"update_{n:02d}" / "state.safetensors").read_text() == f"new {n}"
    old = sorted(p.read_text() for p in (root / "reconstruction" / "set_aside").glob("*/update_*/state.safetensors"))
    assert old == ["old 1", "old 2", "old 3"]
    assert finish_commit(root) is False and Capture.open(root).updates == reopened.updates


def test_stale_builds_of_dead_processes_are_removed_live_ones_kept(tmp_path):
    root = tmp_path / "c"
    _capture_with_steps(root, 1)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    stale = root / "reconstruction" / f".building_{int(dead.stdout)}"
    live = root / "reconstruction" / f".building_{os.getppid()}"
    for folder in (stale, live):
        (folder / "update_02").mkdir(parents=True)
    assert remove_stale_builds(root) == [stale]
    assert live.is_dir() and (root / "reconstruction" / "update_01").is_dir()


def test_a_second_writer_is_refused_with_the_holder_named(tmp_path):
    root = tmp_path / "c"
    _capture_with_steps(root, 1)
    holder = subprocess.Popen([sys.executable, "-c", (
        "import sys, time; from lirm.engine.capture.capture_lock import capture_lock\n"
        f"with capture_lock({str(root)!r}, 'lirm refine'):\n"
        "    print('held', flush=True); time.sleep(60)")], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        with pytest.raises(LirmUserError, match=rf"in use by .*pid {holder.pid}: `lirm refine`.*wait until it has finished"):
            with capture_lock(root, "lirm reconstruct"):
                pass
    finally:
        holder.kill()
        holder.wait()
    with capture_lock(root, "lirm reconstruct"):  # the killed holder's lock went with it
        pass
