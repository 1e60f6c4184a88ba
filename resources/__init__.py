"""lirm.resources: data files that ship with the package (checkpoints, model cards, presets)."""

from pathlib import Path

RESOURCE_DIR = Path(__file__).resolve().parent


def resource_path(name: str) -> Path:
    """Absolute path of a shipped resource file; raises FileNotFoundError naming it if absent."""
    path = RESOURCE_DIR / name
    if not path.exists():
        raise FileNotFoundError(f"resource {name!r} is not installed in {RESOURCE_DIR}")
    return path
