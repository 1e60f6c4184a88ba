"""What `lirm render ASSET` accepts: a model file, or the name of a built-in procedural object."""

from __future__ import annotations

from pathlib import Path

from lirm.engine.errors import AssetLoadError
from lirm.engine.synth.procedural_objects import BUILTIN_OBJECTS, make_builtin_object

from .model_loader import SUPPORTED_SUFFIXES, LoadedModel, load_model


def resolve_asset(name_or_path: str | Path, seed: int = 0) -> LoadedModel:
    """A built-in object by name (`vase`, `mug`, ...) or a .gltf/.glb/.obj file."""
    if isinstance(name_or_path, str) and name_or_path.strip().lower() in BUILTIN_OBJECTS:
        name = name_or_path.strip().lower()
        return LoadedModel(meshes=make_builtin_object(name, seed=seed), warnings=[], source=Path(f"builtin:{name}"))
    path = Path(name_or_path)
    if not path.exists() and path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise AssetLoadError(
            f"{name_or_path}: neither a model file nor a built-in object; "
            f"pass a {', '.join(SUPPORTED_SUFFIXES)} file or one of: {', '.join(BUILTIN_OBJECTS)}"
        )
    return load_model(path)
