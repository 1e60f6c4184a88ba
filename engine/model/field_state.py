"""A refined reconstruction state on disk: the field itself (planes, NDE panoramas and the heads'
weights) rather than the tokens a model decodes, since a per-scene refinement (engine/refine/)
optimises the planes and heads directly and may raise the planes' resolution.

`load_field` reads either kind of state, so export, guidance, evaluation and the app treat an
update's state and a refined one alike.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write

from .config import LIRMConfig
from .field import Field, FieldHeads

FORMAT = "lirm-field/1"


def save_field_state(field: Field, path: str | Path, updates: int, extra: dict | None = None) -> Path:
    tensors = {"planes": field.planes.detach().float().cpu().contiguous().clone()}
    if field.panoramas is not None:
        tensors["panoramas"] = field.panoramas.detach().float().cpu().contiguous().clone()
    for name, value in field.heads.state_dict().items():
        tensors[f"heads.{name}"] = value.detach().float().cpu().contiguous().clone()
    for name, value in tensors.items():
        if not torch.isfinite(value).all():
            raise LirmUserError(f"the refined field's {name} holds NaN or infinite values; it was not saved to {path}")
    metadata = {"format": FORMAT, "updates": str(updates), "signature": field.config.signature(),
                "config": json.dumps(field.config.to_dict()), "extra": json.dumps(extra or {})}
    if field.fitted_beta is not None:  # (states saved before 2026-11-28 have none: exported at their zero level)
        metadata["fitted_beta"] = repr(float(field.fitted_beta))
    return atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=metadata))


def state_format(path: str | Path) -> str | None:
    """The `format` of a state file's header (None when it has none)."""
    try:
        with safe_open(str(path), framework="pt") as f:
            return (f.metadata() or {}).get("format")
    except (SafetensorError, OSError, ValueError) as err:
        raise LirmUserError(f"reconstruction state {path} is corrupt or truncated ({err}); run the update or refinement again") from err


def load_field_state(path: str | Path, device: str | torch.device = "cpu") -> tuple[Field, dict]:
    path = Path(path)
    if not path.is_file():
        raise LirmUserError(f"refined state {path} does not exist")
    try:
        with safe_open(str(path), framework="pt", device=str(device)) as f:
            meta = f.metadata() or {}
            if meta.get("format") != FORMAT:
                raise LirmUserError(f"{path} is not a refined LIRM field (format {meta.get('format')!r})")
            tensors = {k: f.get_tensor(k) for k in f.keys()}
        config = LIRMConfig.from_dict(json.loads(meta["config"]))
        extra = json.loads(meta.get("extra") or "{}")
        fitted_beta = float(meta["fitted_beta"]) if "fitted_beta" in meta else None
    except (SafetensorError, OSError, ValueError, KeyError, TypeError) as err:
        raise LirmUserError(f"refined state {path} is corrupt or truncated ({err}); run `lirm refine` again") from err
    heads = FieldHeads(config).to(device)
    try:
        heads.load_state_dict({k[len("heads."):]: v for k, v in tensors.items() if k.startswith("heads.")})
    except RuntimeError as err:
        raise LirmUserError(f"refined state {path} does not fit its own architecture ({str(err).splitlines()[0]}); "
                            f"run `lirm refine` again") from err
    heads.eval()
    for p in heads.parameters():
        p.requires_grad_(False)
    extra["updates"] = int(meta.get("updates", 0))
    return Field(config, heads, tensors["planes"], tensors.get("panoramas"), fitted_beta), extra


def load_field(path: str | Path, model=None, device: str | torch.device = "cpu") -> Field:
    """The field of any reconstruction state: a refined one as saved, an update's tokens decoded by
    `model` (which must then be given, and of the architecture that made them)."""
    if state_format(path) == FORMAT:
        return load_field_state(path, device)[0]
    from .state_file import load_state

    if model is None:
        raise LirmUserError(f"{path} holds an update's tokens; decoding them needs the model that made them")
    with torch.inference_mode():
        return model.decode(load_state(path, device=str(device)))
