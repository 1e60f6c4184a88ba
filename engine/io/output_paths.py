"""An output the user names, checked before any work starts: a sentence naming the path and the fix
instead of an OSError traceback after minutes of work.

`check_writable_output` looks at the path (a file where a folder is wanted, or the other way round),
then creates and removes a temporary file where the output would go: in the folder itself, or in the
nearest folder that exists above it when the output's folders are still to be made (nothing is left
behind: a start that fails later creates nothing). An OSError there (read-only file system, no
permission, a system folder such as /proc or /sys) becomes a LirmUserError; a full disk a
LirmResourceError.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path

from lirm.engine.errors import LirmResourceError, LirmUserError


def check_writable_output(path: str | Path, what: str, *, folder: bool = False, make_parents: bool = True,
                          example: str | None = None) -> Path:
    """Raise unless `path` can be written. `what`: the output in the user's words with its option
    ("the capture folder (-o)"); `folder`: the output is a folder (else a file); `make_parents`: the
    command creates missing folders above it (else they must exist); `example`: a file name to suggest
    when a folder is given for a file."""
    path = Path(path)
    if folder and path.exists() and not path.is_dir():
        raise LirmUserError(f"{path} is a file, not a folder: {what} must be a folder that does not exist yet "
                            f"(or an empty one); choose another name, e.g. {_sibling(path, '_capture')}")
    if not folder and path.is_dir():
        name = example or "output" + (path.suffix or "")
        raise LirmUserError(f"cannot write {what} {path}: it is a folder; name a file, e.g. {path / name}")
    where = path if folder and path.is_dir() else path.parent
    if not where.exists() and not make_parents:
        raise LirmUserError(f"cannot write {what} {path}: the folder {where} does not exist; create it first "
                            f"or choose a folder that exists")
    probe = where
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise LirmUserError(f"cannot write {what} {path}: {probe} is a file, not a folder, so nothing can be made "
                            f"under it; choose another place")
    try:
        fd, name = tempfile.mkstemp(dir=probe, prefix=".lirm-write-test-")
        os.close(fd)
        os.unlink(name)
    except OSError as err:
        raise _unwritable(path, what, probe, err) from None
    return path


def _unwritable(path: Path, what: str, folder: Path, err: OSError) -> LirmUserError:
    if err.errno in (errno.ENOSPC, errno.EDQUOT):
        return LirmResourceError(f"cannot write {what} {path}: the disk holding {folder} is full; free some space "
                                 f"or choose a folder on another disk")
    if err.errno == errno.EROFS:
        reason = f"{folder} is on a read-only file system"
    elif err.errno in (errno.EACCES, errno.EPERM):
        reason = f"you have no permission to write in {folder}"
    else:
        reason = f"{folder} does not accept new files ({err.strerror or err})"
    return LirmUserError(f"cannot write {what} {path}: {reason}; choose a folder you can write to "
                         f"(e.g. under {Path.home()})")


def _sibling(path: Path, suffix: str) -> Path:
    return path.with_name(path.stem + suffix)
