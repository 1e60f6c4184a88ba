"""Crash-safe steps of a capture's reconstruction history.

New steps (LIRM updates, refinements) are built in a hidden folder, `reconstruction/.building_<pid>/`,
beside the history they will replace or extend. Nothing the history lists is touched until they are
all finished. Then a journal, `reconstruction/.commit.json`, records what the commit does (which
steps are set aside, which folders move in, the new history entries), and `finish_commit` carries
it out: the replaced folders go to `reconstruction/set_aside/<time>/` (never deleted), the new ones
move into place, capture.json is rewritten, the journal is removed.

- Killed (or Ctrl-C, or out of memory) before the journal exists: the capture is as it was; the
  hidden folder is removed by the next run that builds one (`remove_stale_builds`).
- Killed after: the next `Capture.open` finishes the commit. Every step checks what is already done,
  so finishing twice changes nothing.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_json

JOURNAL_NAME = ".commit.json"
BUILD_PREFIX = ".building_"


def reconstruction_dir(root: Path) -> Path:
    return Path(root) / "reconstruction"


def step_folder_name(number: int) -> str:
    return f"update_{number:02d}"


class HistoryBuild:
    """A hidden folder where new history steps are built, then committed in one go or abandoned.

    Use as a context manager: leaving the block by an exception (KeyboardInterrupt and MemoryError
    included) abandons the build and leaves the capture as it was."""

    def __init__(self, capture) -> None:
        self.capture = capture
        self.root = Path(capture.root)
        self.staging = reconstruction_dir(self.root) / f"{BUILD_PREFIX}{os.getpid()}"
        self.committed = False

    def __enter__(self) -> "HistoryBuild":
        remove_stale_builds(self.root)
        shutil.rmtree(self.staging, ignore_errors=True)
        self.staging.mkdir(parents=True)
        return self

    def __exit__(self, kind, value, tb) -> None:
        if not self.committed:
            self.abandon()

    def folder(self, number: int) -> Path:
        """Where step `number` is built; it becomes reconstruction/update_NN/ at the commit."""
        path = self.staging / step_folder_name(number)
        path.mkdir(parents=True, exist_ok=True)
        return path

    def final_state_path(self, number: int) -> str:
        """The state file of step `number` as capture.json lists it (relative to the capture)."""
        return f"reconstruction/{step_folder_name(number)}/state.safetensors"

    def commit(self, keep: int, entries: list[dict], summary: dict | None = None, log: list[dict] | None = None) -> None:
        """The history becomes its first `keep` steps and then `entries` (whose folders were built
        here); the steps after `keep` are set aside. `summary`: the new reconstruction/summary.json."""
        replaced = list(self.capture.updates[keep:])
        journal = {
            "keep": keep,
            "replaced": replaced,
            "entries": entries,
            "staging": self.staging.name,
            "aside": f"set_aside/{time.strftime('%Y%m%d-%H%M%S')}",
            "summary": summary,
            "log": log or [],
        }
        atomic_write_json(reconstruction_dir(self.root) / JOURNAL_NAME, journal)
        self.committed = True
        finish_commit(self.root)
        data = json.loads((self.root / "capture.json").read_text(encoding="utf-8"))
        self.capture.updates = data.get("updates", [])
        self.capture.history = data.get("history", [])

    def abandon(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)


def finish_commit(root: str | Path) -> bool:
    """Carry out a pending commit of the history (see the module's text); True if there was one."""
    root = Path(root)
    recon = reconstruction_dir(root)
    journal_path = recon / JOURNAL_NAME
    if not journal_path.is_file():
        return False
    try:
        journal = json.loads(journal_path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise LirmUserError(f"{journal_path} cannot be read ({exc}): an interrupted change of the reconstruction "
                            f"history. Remove that file to keep the history as capture.json lists it") from None
    staging = recon / journal["staging"]
    aside = recon / journal["aside"]
    new_names = {Path(e["state"]).parent.name for e in journal["entries"]}
    # 1. The replaced steps' folders go aside; one whose name a new step takes only while that new
    #    step is still waiting in the staging folder (afterwards the name holds the new step).
    for entry in journal["replaced"]:
        folder = root / Path(entry["state"]).parent
        if not folder.is_dir():
            continue
        if folder.name in new_names and not (staging / folder.name).is_dir():
            continue
        aside.mkdir(parents=True, exist_ok=True)
        shutil.move(str(folder), str(aside / folder.name))
    # 2. The new steps move into place (a leftover folder of the same name that no entry listed is
    #    set aside first, never overwritten).
    for name in sorted(new_names):
        built = staging / name
        if not built.is_dir():
            continue
        target = recon / name
        if target.exists():
            aside.mkdir(parents=True, exist_ok=True)
            shutil.move(str(target), str(aside / name))
        _move_into_place(built, target)
    # 3. capture.json lists the new history.
    capture_path = root / "capture.json"
    data = json.loads(capture_path.read_text(encoding="utf-8"))
    data["updates"] = data.get("updates", [])[:journal["keep"]] + journal["entries"]
    history = data.setdefault("history", [])
    for item in journal["log"]:
        if item not in history:
            history.append(item)
    if journal["replaced"]:
        note = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "action": "history",
                "set_aside": [e.get("update") for e in journal["replaced"]], "to": f"reconstruction/{journal['aside']}"}
        if not any(h.get("action") == "history" and h.get("to") == note["to"] for h in history):
            history.append(note)
    atomic_write_json(capture_path, data)
    if journal.get("summary") is not None:
        atomic_write_json(recon / "summary.json", journal["summary"])
    shutil.rmtree(staging, ignore_errors=True)
    journal_path.unlink(missing_ok=True)
    return True


def _move_into_place(built: Path, target: Path) -> None:
    os.replace(built, target)  # one rename on the same filesystem: the step is there whole or not at all


def remove_stale_builds(root: str | Path) -> list[Path]:
    """Remove hidden build folders left by runs that are no longer alive (killed before their commit)."""
    recon = reconstruction_dir(Path(root))
    removed = []
    if not recon.is_dir() or (recon / JOURNAL_NAME).exists():
        return removed
    for folder in recon.glob(f"{BUILD_PREFIX}*"):
        pid = folder.name[len(BUILD_PREFIX):].split("_")[-1]
        if pid.isdigit() and int(pid) != os.getpid() and _alive(int(pid)):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
