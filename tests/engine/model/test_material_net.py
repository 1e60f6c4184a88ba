"""The image-space material network: shapes at any photo size, a safetensors round trip, and refusals
of files that are not one."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.model.material_net import (PRESETS, MaterialNet, load_material_net, predict_materials,
                                            save_material_net)


def _photos(count: int, size: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    masks = np.zeros((count, size, size), np.float32)
    masks[:, size // 4: 3 * size // 4, size // 4: 3 * size // 4] = 1.0
    images = np.where(masks[..., None] > 0, rng.uniform(0, 1, (count, size, size, 3)), 1.0).astype(np.float32)
    return images, masks


def test_predictions_come_back_at_each_photos_own_size_and_in_range():
    torch.manual_seed(0)
    net = MaterialNet(PRESETS["small"])
    for height, width in ((128, 128), (90, 150), (300, 200)):
        images, masks = _photos(2, max(height, width))
        maps = predict_materials(net, images[:, :height, :width], masks[:, :height, :width])
        assert maps.metallic.shape == maps.roughness.shape == (2, height, width)
        assert maps.albedo.shape == (2, height, width, 3)
        for a in (maps.metallic, maps.roughness, maps.albedo):
            assert np.isfinite(a).all() and a.min() >= 0.0 and a.max() <= 1.0


def test_weights_round_trip_and_other_files_are_refused_by_name(tmp_path):
    torch.manual_seed(1)
    net = MaterialNet(PRESETS["small"])
    path = save_material_net(net, tmp_path / "m.safetensors", {"steps": 3})
    loaded, meta = load_material_net(path)
    images, masks = _photos(1, 64)
    assert meta == {"steps": 3}
    assert np.array_equal(predict_materials(net, images, masks).metallic, predict_materials(loaded, images, masks).metallic)
    with pytest.raises(LirmUserError, match="must end in .safetensors"):
        save_material_net(net, tmp_path / "m.pt")
    with pytest.raises(LirmUserError, match="not found"):
        load_material_net(tmp_path / "missing.safetensors")
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"not a safetensors file at all")
    with pytest.raises(LirmUserError, match="garbage.safetensors"):
        load_material_net(garbage)
    from safetensors.torch import save_file
    other = tmp_path / "other.safetensors"
    save_file({"w": torch.zeros(2)}, str(other), metadata={"format": "lirm-checkpoint/1"})
    with pytest.raises(LirmUserError, match="not a material network"):
        load_material_net(other)
    broken = MaterialNet(PRESETS["small"])
    with torch.no_grad():
        broken.head.weight[0, 0, 0, 0] = float("nan")
    save_material_net(broken, tmp_path / "nan.safetensors")
    with pytest.raises(LirmUserError, match="NaN"):
        load_material_net(tmp_path / "nan.safetensors")
