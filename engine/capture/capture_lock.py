"""One writer per capture: `lirm capture` (on an existing capture), `reconstruct` and `refine` hold
an exclusive lock on CAPTURE/.lock while they run, so that two of them never write the same update
folders or capture.json at once.

The lock is an `flock` on the file: the system releases it when the process ends, killed or not, so
a crashed run never leaves a capture locked. The file itself only says who holds it, for the message
a second run gets."""

from __future__ import annotations

import fcntl
import json
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from lirm.engine.errors import LirmUserError

LOCK_NAME = ".lock"


@contextmanager
def capture_lock(root: str | Path, what: str | None = None) -> Iterator[None]:
    """Hold the capture's lock for the block, or raise LirmUserError naming the process that holds it."""
    root = Path(root)
    path = root / LOCK_NAME
    if what is None:
        what = " ".join(["lirm", *sys.argv[1:2]])
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        raise LirmUserError(f"{root}: cannot open the capture's lock file {path.name} ({exc.strerror}); "
                            f"check that the folder is writable") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise LirmUserError(f"{root} is in use by {_holder(path)}; wait until it has finished "
                                f"(or stop it) and run this again") from None
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps({"pid": os.getpid(), "command": what,
                                 "since": time.strftime("%Y-%m-%d %H:%M:%S")}).encode())
        try:
            yield
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text(encoding="utf-8") or "{}")
    except (OSError, json.JSONDecodeError):
        info = {}
    if not info:
        return "another LIRM Studio process"
    return f"another LIRM Studio process (pid {info.get('pid')}: `{info.get('command')}`, since {info.get('since')})"
