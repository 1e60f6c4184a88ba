"""The image-space material terms: what they measure, and the per-pixel targets in the views' order."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.model.material_net import PRESETS, MaterialNet, predict_materials, save_material_net
from lirm.engine.refine import image_materials
from lirm.engine.refine.image_materials import image_material_terms, pixel_material_targets


def test_the_terms_vanish_at_the_target_and_the_albedo_term_reads_only_chromaticity():
    targets = torch.tensor([[1.0, 0.2, 0.8, 0.6, 0.2], [0.0, 0.7, 0.1, 0.1, 0.1]])
    albedo = targets[:, 2:5] * torch.tensor([[0.5], [2.0]])  # brighter or darker, the same colour
    terms = image_material_terms(targets[:, 1], targets[:, 0], albedo, targets, with_albedo=True)
    assert float(terms["image_metallic"]) == float(terms["image_roughness"]) == pytest.approx(0.0) and float(terms["image_albedo"]) == pytest.approx(0.0, abs=1e-6)
    wrong = image_material_terms(targets[:, 1], 1.0 - targets[:, 0], albedo.flip(-1), targets, with_albedo=True)
    assert float(wrong["image_metallic"]) == pytest.approx(1.0) and float(wrong["image_roughness"]) == pytest.approx(0.0) and float(wrong["image_albedo"]) > 0.1
    assert "image_albedo" not in image_material_terms(targets[:, 1], targets[:, 0], albedo, targets, with_albedo=False)


def test_the_shade_term_reads_the_albedos_relative_brightness_not_its_scale():
    targets = torch.tensor([[0.0, 0.5, 0.8, 0.8, 0.8], [0.0, 0.5, 0.2, 0.2, 0.2], [0.0, 0.5, 0.4, 0.1, 0.1]])
    scaled = image_material_terms(targets[:, 1], targets[:, 0], targets[:, 2:5] * 0.3, targets, with_albedo=False, with_shade=True)
    assert float(scaled["image_albedo_shade"]) == pytest.approx(0.0, abs=1e-6)  # the whole object darker: free
    flattened = torch.full((3, 3), 0.5)  # a dark paint lifted to the bright one's level, as baked shading would
    shaded = image_material_terms(targets[:, 1], targets[:, 0], flattened, targets, with_albedo=False, with_shade=True)
    assert float(shaded["image_albedo_shade"]) > 0.3
    assert "image_albedo_shade" not in image_material_terms(targets[:, 1], targets[:, 0], flattened, targets, with_albedo=True)


def test_targets_follow_the_views_pixel_order(tmp_path):
    torch.manual_seed(0)
    path = save_material_net(MaterialNet(PRESETS["small"]), tmp_path / "m.safetensors")
    rng = np.random.default_rng(0)
    images = rng.uniform(0, 1, (2, 24, 40, 3)).astype(np.float32)
    masks = (rng.uniform(0, 1, (2, 24, 40)) > 0.3).astype(np.float32)
    targets, said = pixel_material_targets(images, masks, path)
    flat = targets.numpy()
    assert "m.safetensors" in said
    from lirm.engine.model.material_net import load_material_net
    maps = predict_materials(load_material_net(path)[0], images, masks)
    assert flat.shape == (2 * 24 * 40, 5)
    v, y, x = 1, 17, 33
    k = v * 24 * 40 + y * 40 + x
    assert flat[k, 0] == pytest.approx(maps.metallic[v, y, x]) and flat[k, 1] == pytest.approx(maps.roughness[v, y, x])
    assert flat[k, 2:5] == pytest.approx(maps.albedo[v, y, x])


def test_without_a_network_the_prior_says_how_to_get_one(monkeypatch):
    monkeypatch.setattr(image_materials, "shipped_material_net", lambda: None)
    with pytest.raises(LirmUserError, match="lirm train-materials"):
        pixel_material_targets(np.ones((1, 8, 8, 3), np.float32), np.ones((1, 8, 8), np.float32))
