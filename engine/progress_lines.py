"""Progress that a log file can show: a tqdm bar on a terminal, and otherwise plain lines, flushed
as they happen (one when a stage starts, then at most one every `every` seconds and one at the end).
tqdm with `disable=None` writes nothing when stderr is not a terminal, so `lirm capture > log 2>&1`
showed nothing for minutes and then everything at the end."""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO


def progress_bar(desc: str = "", total: int | None = None, unit: str = "it", file: TextIO | None = None,
                 leave: bool = True, every: float = 10.0, disable: bool | None = None, **tqdm_options: Any):
    """A tqdm bar when `file` (stderr) is a terminal, else a LineProgress with the same methods."""
    file = file or sys.stderr
    if disable is True:
        from tqdm import tqdm

        return tqdm(disable=True)
    if _is_terminal(file):
        from tqdm import tqdm

        return tqdm(desc=desc, total=total, unit=unit, file=file, leave=leave, **tqdm_options)
    return LineProgress(desc, total, unit, file, every)


class LineProgress:
    """The subset of tqdm's interface the commands use, written as lines."""

    def __init__(self, desc: str, total: int | None, unit: str, file: TextIO, every: float) -> None:
        self.desc, self.total, self.unit, self.file, self.every = desc, total, unit, file, every
        self.n = 0
        self.postfix = ""
        self._start = time.monotonic()
        self._last_line = 0.0
        self._last_text = ""
        self._closed = False
        self._write(force=True)

    def __enter__(self) -> "LineProgress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def update(self, k: int = 1) -> None:
        self.n += k
        self._write()

    def refresh(self) -> None:
        self._write()

    def set_description(self, desc: str, refresh: bool = True) -> None:
        self.desc = desc
        if refresh:
            self._write()

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        self.postfix = text
        if refresh:
            self._write()

    def set_postfix(self, ordered_dict=None, refresh: bool = True, **kwargs: Any) -> None:
        items = dict(ordered_dict or {}, **kwargs)
        self.set_postfix_str(", ".join(f"{k}={v}" for k, v in items.items()), refresh)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._write(force=True, unless_same=True)

    def _write(self, force: bool = False, unless_same: bool = False) -> None:
        now = time.monotonic()
        done = self.total is not None and self.n >= self.total
        if not (force or done or now - self._last_line >= self.every):
            return
        total = f"/{self.total}" if self.total is not None else ""
        share = f" ({100.0 * self.n / self.total:.0f}%)" if self.total else ""
        text = f"{self.desc}: {self.n}{total} {self.unit}{share}" + (f", {self.postfix}" if self.postfix else "")
        if text == self._last_text and (unless_same or not force):
            return
        self.file.write(f"{text} [{now - self._start:.0f} s]\n")
        self.file.flush()
        self._last_line, self._last_text = now, text


def _is_terminal(file: TextIO) -> bool:
    try:
        return file.isatty()
    except (AttributeError, ValueError):
        return False
