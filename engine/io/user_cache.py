"""The user's cache folder for LIRM Studio: $XDG_CACHE_HOME/lirm, else ~/.cache/lirm (crash reports,
fetched weights, the app's job logs)."""

from __future__ import annotations

import os
from pathlib import Path


def user_cache_folder() -> Path:
    cache = os.environ.get("XDG_CACHE_HOME")
    return (Path(cache) if cache and Path(cache).is_absolute() else Path.home() / ".cache") / "lirm"
