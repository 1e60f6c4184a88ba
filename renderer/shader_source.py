"""Load GLSL sources that live in renderer/shaders/, resolving `#include "file"` lines once each."""

from __future__ import annotations

import re
from functools import lru_cache
from pathlib import Path

SHADER_DIR = Path(__file__).resolve().parent / "shaders"
_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.MULTILINE)


@lru_cache(maxsize=None)
def shader_source(name: str) -> str:
    """The source of shaders/<name> with its includes expanded in place (each file at most once)."""
    return _expand(name, seen=set())


def _expand(name: str, seen: set[str]) -> str:
    if name in seen:
        return ""
    seen.add(name)
    text = (SHADER_DIR / name).read_text(encoding="utf-8")
    return _INCLUDE.sub(lambda m: _expand(m.group(1), seen), text)
