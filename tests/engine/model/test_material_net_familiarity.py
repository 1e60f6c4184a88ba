"""The material network's check on itself: stable on photos like its training's, unstable on others."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.model.material_net import load_material_net, object_exposure, predict_materials
from lirm.engine.model.material_net_familiarity import LIMIT, Familiarity, material_net_familiarity
from lirm.engine.refine.image_materials import shipped_material_net


@pytest.fixture(scope="module")
def shipped_net():
    return load_material_net(shipped_material_net())[0]


def _inputs(obj):
    views = obj.views.select([i for s in obj.protocol.input_sets for i in s])
    return views.image, views.mask


def test_a_held_out_object_of_its_own_kind_is_familiar(shipped_net, renderer):
    from lirm.engine.evaluation.heldout_sets import synthetic_heldout

    (mug,) = synthetic_heldout(renderer, 1, 128, surface_points=100, first=9)  # beyond the objects the limit was set on
    images, masks = _inputs(mug)
    familiarity = material_net_familiarity(shipped_net, images, masks)
    assert familiarity.familiar and familiarity.unstable_fraction < LIMIT / 2, familiarity
    assert "material network used" in familiarity.describe()
    # What the refinement then holds its materials to is the prediction on the photos as they are.
    direct = predict_materials(shipped_net, images, masks)
    for name in ("metallic", "roughness", "albedo"):
        np.testing.assert_array_equal(getattr(familiarity.as_photographed, name), getattr(direct, name))


def test_a_plain_white_bunny_is_not(shipped_net, renderer, shared_data):
    from lirm.engine.evaluation.heldout_sets import gltf_heldout

    (bunny,) = gltf_heldout(renderer, [shared_data / "pbr_models" / "pmndrs_bunny_untextured.glb"],
                            [shared_data / "envmaps" / "forest_slope_1k.hdr"], 128, surface_points=100)
    familiarity = material_net_familiarity(shipped_net, *_inputs(bunny))
    assert not familiarity.familiar, familiarity
    assert "not used" in familiarity.describe() and f"below {100 * LIMIT:.0f}%" in familiarity.describe()


def test_photos_without_an_object_are_never_familiar(shipped_net):
    images, masks = np.ones((2, 32, 32, 3), np.float32), np.zeros((2, 32, 32), np.float32)
    assert material_net_familiarity(shipped_net, images, masks) == Familiarity(1.0)


def test_the_exposure_variant_changes_the_object_and_not_the_white_around_it():
    images = np.full((1, 4, 4, 3), 0.5, np.float32)
    images[0, 0, 0] = 1.0  # a background pixel (mask 0), white
    masks = np.ones((1, 4, 4), np.float32)
    masks[0, 0, 0] = 0.0
    brighter = object_exposure(images, masks, 1.15)
    assert brighter[0, 0, 0].tolist() == [1.0, 1.0, 1.0]
    np.testing.assert_allclose(brighter[0, 1:, 1:], 0.575, rtol=1e-6)
    np.testing.assert_allclose(object_exposure(images, masks, 3.0)[0, 2, 2], 1.0)  # clipped as a photo would be
