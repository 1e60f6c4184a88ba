"""The capture the app had open last, so that `lirm app` reopens where the user was.

Kept in $XDG_CONFIG_HOME/lirm/recent.json (default ~/.config/lirm/recent.json); the captures
themselves hold everything else (app_state.json inside each one).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from lirm.engine.io.atomic_files import atomic_write_json


def recent_file() -> Path:
    return Path(os.environ.get("XDG_CONFIG_HOME") or Path.home() / ".config") / "lirm" / "recent.json"


def last_capture() -> Path | None:
    try:
        path = Path(json.loads(recent_file().read_text(encoding="utf-8"))["last_capture"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return path if (path / "capture.json").is_file() else None


def remember_capture(path: Path) -> None:
    try:
        atomic_write_json(recent_file(), {"last_capture": str(Path(path).resolve())})
    except OSError:
        pass  # a read-only home only loses the convenience
