"""A reconstruction state on disk: the plane and NDE tokens in a .safetensors file, with how many
updates made it and the architecture signature in the header (a state only fits its own model)."""

from __future__ import annotations

from pathlib import Path

from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write

from .lirm import ReconState

FORMAT = "lirm-state/1"


def save_state(state: ReconState, path: str | Path) -> Path:
    tensors = {"plane_tokens": state.plane_tokens.detach().cpu().contiguous().clone()}
    if state.nde_tokens is not None:
        tensors["nde_tokens"] = state.nde_tokens.detach().cpu().contiguous().clone()
    metadata = {"format": FORMAT, "updates": str(state.updates), "signature": state.signature}
    return atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=metadata))


def load_state(path: str | Path, device: str = "cpu") -> ReconState:
    path = Path(path)
    if not path.exists():
        raise LirmUserError(f"reconstruction state {path} does not exist")
    try:
        with safe_open(str(path), framework="pt", device=str(device)) as f:
            meta = f.metadata() or {}
            if meta.get("format") != FORMAT:
                raise LirmUserError(f"{path} is not a LIRM reconstruction state (format {meta.get('format')!r})")
            tensors = {k: f.get_tensor(k) for k in f.keys()}
    except (SafetensorError, OSError, ValueError) as err:
        raise LirmUserError(f"reconstruction state {path} is corrupt or truncated ({err}); run the update again") from err
    return ReconState(tensors["plane_tokens"], tensors.get("nde_tokens"), int(meta["updates"]), meta["signature"])
