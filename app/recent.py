"""The captures the app had open, most recent first, so that `lirm app` reopens where the user was and
File > Recent lists the others.

Kept in $XDG_CONFIG_HOME/lirm/recent.json (default ~/.config/lirm/recent.json); the captures
themselves hold everything else (app_state.json inside each one).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from lirm.engine.io.atomic_files import atomic_write_json

KEPT = 8


def recent_file() -> Path:
    return Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "lirm" / "recent.json"


def _saved() -> list[str]:
    try:
        data = json.loads(recent_file().read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    if not isinstance(data, dict):
        return []
    listed = data.get("recent")
    paths = [p for p in listed if isinstance(p, str)] if isinstance(listed, list) else []
    last = data.get("last_capture")  # what versions before the list wrote
    return ([last] if isinstance(last, str) and last not in paths else []) + paths


def recent_captures() -> list[Path]:
    """Captures opened before, most recent first; those that are gone are left out."""
    return [Path(p) for p in _saved() if (Path(p) / "capture.json").is_file()]


def last_capture() -> Path | None:
    found = recent_captures()
    return found[0] if found else None


def remember_capture(path: Path) -> None:
    path_text = str(Path(path).resolve())
    paths = [path_text] + [p for p in _saved() if p != path_text]
    try:
        atomic_write_json(recent_file(), {"last_capture": path_text, "recent": paths[:KEPT]})
    except OSError:
        pass  # a read-only home only loses the convenience
