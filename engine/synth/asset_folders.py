"""User folders of glTF models and HDR environments as training-data sources.

Every file is tried once, up front, with the same loaders the renderer uses: what loads is used,
what does not is reported by name with the reason, and training goes on with the rest. A folder
with nothing usable is an error before any compute is spent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from lirm.engine.assets.environment_files import load_environment_file
from lirm.engine.assets.model_loader import load_model
from lirm.engine.errors import LirmUserError

MODEL_SUFFIXES = (".gltf", ".glb")
ENVIRONMENT_SUFFIXES = (".hdr", ".exr")


@dataclass
class FolderScan:
    folder: Path
    usable: list[Path] = field(default_factory=list)
    problems: list[tuple[Path, str]] = field(default_factory=list)  # (file, why it was skipped)

    def report(self, what: str) -> str:
        lines = [f"{self.folder}: {len(self.usable)} usable {what}, {len(self.problems)} skipped"]
        lines += [f"  skipped {p.name}: {why}" for p, why in self.problems]
        return "\n".join(lines)


def _files(folder: Path, suffixes: tuple[str, ...], what: str) -> list[Path]:
    folder = Path(folder).expanduser()
    if not folder.is_dir():
        raise LirmUserError(f"{folder}: not a folder; pass a folder of {what} ({', '.join(suffixes)})")
    return sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix.lower() in suffixes)


def _require_some(scan: FolderScan, suffixes: tuple[str, ...], what: str) -> FolderScan:
    if not scan.usable:
        detail = "; ".join(f"{p.name}: {why}" for p, why in scan.problems[:5]) or f"no {', '.join(suffixes)} files in it"
        raise LirmUserError(f"{scan.folder}: no usable {what} ({detail}); fix the files or pass another folder")
    return scan


def scan_model_folder(folder: str | Path) -> FolderScan:
    """Every .gltf/.glb under `folder` (recursively) that loads and has triangles."""
    files = _files(Path(folder), MODEL_SUFFIXES, "glTF models")
    scan = FolderScan(Path(folder))
    for path in files:
        try:
            model = load_model(path)
            if not model.meshes:
                raise LirmUserError("it has no triangle meshes")
        except LirmUserError as err:
            scan.problems.append((path, _reason(err, path)))
            continue
        except Exception as err:  # a loader bug on a strange file must not stop the scan of the others
            scan.problems.append((path, f"could not be loaded ({type(err).__name__}: {err})"))
            continue
        scan.usable.append(path)
    return _require_some(scan, MODEL_SUFFIXES, "glTF models")


def scan_environment_folder(folder: str | Path) -> FolderScan:
    """Every .hdr/.exr under `folder` (recursively) that decodes to a finite equirectangular image."""
    files = _files(Path(folder), ENVIRONMENT_SUFFIXES, "HDR environments")
    scan = FolderScan(Path(folder))
    for path in files:
        try:
            load_environment_file(path)
        except LirmUserError as err:
            scan.problems.append((path, _reason(err, path)))
            continue
        except Exception as err:
            scan.problems.append((path, f"could not be decoded ({type(err).__name__}: {err})"))
            continue
        scan.usable.append(path)
    return _require_some(scan, ENVIRONMENT_SUFFIXES, "HDR environments")


def _reason(err: Exception, path: Path) -> str:
    """The loader's message without the path it starts with (the report names the file already)."""
    text = str(err)
    for prefix in (f"{path}: ", f"{path.name}: "):
        if text.startswith(prefix):
            return text[len(prefix):]
    return text
