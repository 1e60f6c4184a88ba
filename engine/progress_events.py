"""Machine-readable progress for a parent process (the app runs long work as `lirm` subprocesses).

With LIRM_PROGRESS_EVENTS=1 in the environment, every progress report of a command is also written
to stderr as one line: `LIRM-PROGRESS {"stage": ..., "done": ..., "total": ...}`. Without it,
nothing changes for a person at a terminal.
"""

from __future__ import annotations

import json
import os
import sys

PREFIX = "LIRM-PROGRESS "
ENV = "LIRM_PROGRESS_EVENTS"


def enabled() -> bool:
    return os.environ.get(ENV) == "1"


def emit(stage: str, done: int, total: int) -> None:
    if enabled():
        print(PREFIX + json.dumps({"stage": stage, "done": int(done), "total": int(total)}), file=sys.stderr, flush=True)


def parse(line: str) -> dict | None:
    """The event on a line of a child's stderr, or None when the line is ordinary output."""
    if not line.startswith(PREFIX):
        return None
    try:
        event = json.loads(line[len(PREFIX):])
    except json.JSONDecodeError:
        return None
    return event if isinstance(event, dict) and {"stage", "done", "total"} <= set(event) else None
