"""The object's real size, stated by the user: stored in capture.json, read by every export (which is
then in metres; without it the scale is the photos' arbitrary one, and the export says so)."""

from __future__ import annotations

import re
from pathlib import Path

from .capture_folder import Capture
from .capture_lock import capture_lock

DIMENSIONS = ("height", "width")  # height along +Z (up), width the largest horizontal extent


def parse_real_size(text: str) -> tuple[str, float]:
    """'height=0.095', 'width=12cm', 'height=95 mm' -> ('height', metres). ValueError when unreadable."""
    match = re.fullmatch(r"\s*(height|width)\s*=\s*([0-9]*\.?[0-9]+)\s*(m|cm|mm)?\s*", text)
    if not match:
        raise ValueError(f"{text!r}: write height=METRES or width=METRES (e.g. height=0.095 or height=9.5cm)")
    value = float(match.group(2)) * {"m": 1.0, "cm": 0.01, "mm": 0.001, None: 1.0}[match.group(3)]
    if not 0.001 <= value <= 100.0:
        raise ValueError(f"{text!r}: {value:g} m is outside 1 mm..100 m")
    return match.group(1), value


def set_real_size(capture_root: str | Path, dimension: str, metres: float, who: str = "lirm capture --real-size") -> None:
    if dimension not in DIMENSIONS or not metres > 0:
        raise ValueError(f"a real size is a positive height or width, got {dimension}={metres}")
    with capture_lock(capture_root, who):
        capture = Capture.open(capture_root)
        capture.settings["real_size"] = {dimension: float(metres)}
        capture.log("real size", **{dimension: float(metres)})
        capture.save()
