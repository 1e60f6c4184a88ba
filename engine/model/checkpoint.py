"""LIRM checkpoints: one .safetensors file holding the weights, with the config in its header.

safetensors only, never pickle: a checkpoint may come from anywhere, and unpickling runs code.
The header's string metadata holds `format`, `config` (JSON), `signature` (the architecture hash,
for tools that only read the header) and `extra` (JSON: training step, whether it is trained, ...).
Every problem a user can cause (wrong file, truncated download, other preset) is a LirmUserError
naming the file and what to do.
"""

from __future__ import annotations

import json
from contextlib import contextmanager
from pathlib import Path

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import save_file

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write

from .config import LIRMConfig, preset
from .lirm import LIRM

FORMAT = "lirm-checkpoint/1"
PICKLE_SUFFIXES = (".pt", ".pth", ".ckpt", ".bin", ".pkl")
# Tensors under this prefix are a training run's state (optimizer moments), not the model's weights:
# a training checkpoint is also a model checkpoint that every loader reads.
TRAINING_PREFIX = "training."


def require_safetensors_name(path: str | Path) -> Path:
    """The path of a checkpoint to write, refused unless it names a .safetensors file (callers that save
    late, e.g. a training run's slim copy, check it before the work starts)."""
    path = Path(path)
    if path.suffix != ".safetensors":
        raise LirmUserError(f"cannot save checkpoint {path}: the file name must end in .safetensors")
    return path


def save_checkpoint(model: LIRM, path: str | Path, *, dtype: torch.dtype | None = None,
                    metadata: dict | None = None, training_tensors: dict[str, torch.Tensor] | None = None) -> Path:
    """Write the model's weights (floating ones cast to `dtype` if given) and config to `path`;
    `training_tensors` (optimizer state) are stored as they are, under TRAINING_PREFIX."""
    path = require_safetensors_name(path)
    config = model.config
    # clone(): safetensors refuses tensors that share memory or are not contiguous.
    tensors = {name: (t.detach().to("cpu", dtype) if dtype is not None and t.is_floating_point()
                      else t.detach().cpu()).contiguous().clone()
               for name, t in model.state_dict().items()}
    for name, t in (training_tensors or {}).items():
        tensors[TRAINING_PREFIX + name] = t.detach().cpu().contiguous().clone()
    # Refuse here rather than write a file that load_checkpoint would reject.
    bad = [n for n, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]
    if bad:
        hint = "save in float32" if dtype not in (None, torch.float32) else "the training diverged; use an earlier step"
        raise LirmUserError(f"not saving checkpoint {path}: weights {_few(bad)} contain NaN or infinite values; {hint}")
    header = {"format": FORMAT, "config": json.dumps(config.to_dict()), "signature": config.signature(),
              "extra": json.dumps(metadata or {})}
    # Atomic: an interrupted save leaves the previous checkpoint, never a truncated one.
    return atomic_write(path, lambda tmp: save_file(tensors, str(tmp), metadata=header))


def peek_checkpoint(path: str | Path) -> tuple[LIRMConfig, dict]:
    """The config and `extra` metadata of a checkpoint, reading only its header."""
    path = _check_path(path)
    with _open(path) as f:
        return _parse_header(path, f.metadata())


def load_checkpoint(path: str | Path, *, expected: LIRMConfig | str | None = None,
                    device: str | torch.device = "cpu") -> tuple[LIRM, dict]:
    """The model (float32, eval mode, on `device`) and the `extra` metadata saved with it.

    `expected` (a config or a preset name) is the architecture the caller wants; a checkpoint of
    another one is refused before its weights are read.
    """
    path = _check_path(path)
    with _open(path) as f:
        config, extra = _parse_header(path, f.metadata())
        if expected is not None:
            _check_expected(path, config, expected)
        try:
            tensors = {name: f.get_tensor(name) for name in f.keys() if not name.startswith(TRAINING_PREFIX)}
        except (SafetensorError, OSError, RuntimeError, ValueError) as e:
            raise _corrupt(path, e) from None
    model = LIRM(config)
    _check_tensors(path, tensors, model.state_dict())
    # Shipped weights are fp16 for size; compute is float32.
    model.load_state_dict({n: t.float() if t.is_floating_point() else t for n, t in tensors.items()})
    return model.to(device).eval(), extra


def load_training_tensors(path: str | Path) -> dict[str, torch.Tensor]:
    """The training-state tensors of a checkpoint (without their prefix); empty for a model-only one."""
    path = _check_path(path)
    with _open(path) as f:
        _parse_header(path, f.metadata())
        try:
            return {name[len(TRAINING_PREFIX):]: f.get_tensor(name) for name in f.keys() if name.startswith(TRAINING_PREFIX)}
        except (SafetensorError, OSError, RuntimeError, ValueError) as e:
            raise _corrupt(path, e) from None


# ---- helpers ----------------------------------------------------------------------------------------
def _few(names: list[str], n: int = 3) -> str:
    more = f" and {len(names) - n} more" if len(names) > n else ""
    return ", ".join(names[:n]) + more


def _corrupt(path: Path, err: Exception) -> LirmUserError:
    return LirmUserError(f"checkpoint {path} is not a valid .safetensors file or is truncated ({err}); "
                         f"download or save it again")


def _check_path(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() in PICKLE_SUFFIXES:
        raise LirmUserError(f"checkpoint {path} is a pickle file; only .safetensors checkpoints are accepted "
                            f"(pickle files can run code when loaded)")
    if path.is_dir():
        found = sorted(path.glob("*.safetensors"))
        if found:
            best = next((p for p in found if p.name == "last.safetensors"), found[-1])
            raise LirmUserError(f"checkpoint {path} is a folder; pass the .safetensors file inside it, e.g. "
                                f"{best} (it holds {_few([p.name for p in found], 5)})")
        raise LirmUserError(f"checkpoint {path} is a folder with no .safetensors file in it; pass the path of a "
                            f".safetensors checkpoint file (a training run writes RUN/last.safetensors)")
    if not path.is_file():
        raise LirmUserError(f"checkpoint {path} does not exist; check the path or train/download one")
    return path


@contextmanager
def _open(path: Path):
    """safe_open (which validates the header) with its errors turned into a LirmUserError naming the file."""
    try:
        f = safe_open(str(path), framework="pt", device="cpu")
    except (SafetensorError, OSError, RuntimeError, ValueError) as e:
        raise _corrupt(path, e) from None
    with f:
        yield f


def _parse_header(path: Path, meta: dict[str, str] | None) -> tuple[LIRMConfig, dict]:
    fmt = (meta or {}).get("format")
    if fmt is None:
        raise LirmUserError(f"{path} is a safetensors file but not a LIRM checkpoint (no 'format' in its header); "
                            f"pass a checkpoint saved by lirm")
    if fmt != FORMAT:
        raise LirmUserError(f"checkpoint {path} has format {fmt!r}, but this version of lirm reads {FORMAT!r}; "
                            f"use a matching version of lirm or re-save the checkpoint")
    try:
        config = LIRMConfig.from_dict(json.loads(meta["config"]))
    except (KeyError, TypeError, ValueError) as e:  # JSONDecodeError is a ValueError; bad fields raise TypeError
        raise LirmUserError(f"checkpoint {path} has an unreadable model config ({e}); re-save the checkpoint") from None
    try:
        extra = json.loads(meta.get("extra", "{}"))
        if not isinstance(extra, dict):
            raise ValueError("not a JSON object")
    except ValueError as e:
        raise LirmUserError(f"checkpoint {path} has unreadable 'extra' metadata ({e}); re-save the checkpoint") from None
    return config, extra


def _check_expected(path: Path, config: LIRMConfig, expected: LIRMConfig | str) -> None:
    if isinstance(expected, str):
        try:
            expected = preset(expected)
        except ValueError as e:
            raise LirmUserError(f"cannot load checkpoint {path}: {e}") from None
    if config.signature() == expected.signature():
        return  # same architecture: the name alone does not matter
    if config.name != expected.name:
        raise LirmUserError(f"checkpoint {path} holds the '{config.name}' model but the '{expected.name}' model was "
                            f"asked for; pass --preset {config.name} or a '{expected.name}' checkpoint")
    raise LirmUserError(f"checkpoint {path} holds a '{config.name}' model whose architecture differs from the current "
                        f"'{expected.name}' preset (signature {config.signature()} vs {expected.signature()}); "
                        f"use a checkpoint made by this version of lirm")


def _check_tensors(path: Path, tensors: dict[str, torch.Tensor], wanted: dict[str, torch.Tensor]) -> None:
    """Name the offending tensors: load_state_dict's own message is a wall of text."""
    problems = []
    missing = [n for n in wanted if n not in tensors]
    unexpected = [n for n in tensors if n not in wanted]
    shaped = [f"{n} {tuple(tensors[n].shape)} != {tuple(t.shape)}" for n, t in wanted.items()
              if n in tensors and tensors[n].shape != t.shape]
    for label, names in (("missing", missing), ("unexpected", unexpected), ("mis-shaped", shaped)):
        if names:
            problems.append(f"{len(names)} {label} ({_few(names)})")
    if problems:
        raise LirmUserError(f"checkpoint {path} does not fit its model config: {'; '.join(problems)} tensors; "
                            f"re-save the checkpoint")
    bad = [n for n, t in tensors.items() if t.is_floating_point() and not torch.isfinite(t).all()]
    if bad:
        raise LirmUserError(f"checkpoint {path} has NaN or infinite weights in {_few(bad)}; the training diverged; "
                            f"use an earlier checkpoint")
