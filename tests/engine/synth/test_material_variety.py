"""The material prior's varied scenes: every kind of paint occurs, metal is metal in the G-buffer, a seed is one scene."""

from __future__ import annotations

import numpy as np

from lirm.engine.synth.material_variety import (VarietyConfig, blob_geometry, make_varied_scene, random_material,
                                                split_into_parts, varied_meshes)
from lirm.engine.synth.training_scenes import TrainingSceneConfig


def test_random_materials_are_metals_greys_and_hues_in_range():
    rng = np.random.default_rng(0)
    materials = [random_material(rng, VarietyConfig(), "m") for _ in range(300)]
    metals = [m for m in materials if m.metallic_factor == 1.0]
    paints = [m for m in materials if m.metallic_factor == 0.0]
    assert len(metals) + len(paints) == 300 and 70 < len(metals) < 130
    greys = [m for m in paints if np.ptp(m.base_color_factor[:3]) < 0.05 * max(m.base_color_factor[:3])]
    assert 0.3 < len(greys) / len(paints) < 0.7  # as many greys (white to black) as hues
    for m in materials:
        assert all(0.0 <= c <= 1.0 for c in m.base_color_factor) and 0.0 < m.roughness_factor < 1.0
        assert m.base_color_texture is None and m.metallic_roughness_texture is None


def test_a_blob_splits_into_parts_that_cover_every_face_once():
    rng = np.random.default_rng(3)
    positions, faces = blob_geometry(rng, VarietyConfig())
    assert np.isfinite(positions).all() and faces.max() < len(positions)
    parts = split_into_parts(positions, faces, 3, rng)
    assert 1 <= len(parts) <= 3
    assert sum(len(p) for p in parts) == len(faces)
    assert len({tuple(f) for p in parts for f in p}) == len(faces)


def test_every_kind_of_shape_and_paint_occurs():
    kinds = set()
    for seed in range(60):
        meshes, shape, paint = varied_meshes(np.random.default_rng([1, seed]), VarietyConfig())
        kinds.add(paint)
        if paint == "no metal":
            assert all(m.material.metallic_factor == 0.0 for m in meshes)
        if paint == "parts":
            assert shape in ("blob", "torus")
            # The parts share one set of normals, so that the cuts leave no shading seam.
            assert all(m.normals is meshes[0].normals for m in meshes)
    assert kinds == {"own", "no metal", "repainted", "parts"}


def test_a_seed_is_one_scene_and_its_metal_is_in_the_gbuffer(renderer):
    scene = TrainingSceneConfig(views=2, size=48, supersample=1, fov_deg=(30.0, 70.0))
    # Find a scene of metal parts, then render it twice.
    seed = next(s for s in range(100) if _all_metal_parts(s))
    a, b = make_varied_scene(renderer, seed, scene), make_varied_scene(renderer, seed, scene)
    assert (a.shape, a.paint) == (b.shape, b.paint)
    np.testing.assert_array_equal(a.views.image, b.views.image)
    inside = a.views.mask > 0.99
    assert inside.sum() > 50 and np.allclose(a.views.metallic[inside], 1.0, atol=1e-3)
    other = make_varied_scene(renderer, seed + 1, scene)
    assert not np.array_equal(other.views.image, a.views.image)


def _all_metal_parts(seed: int) -> bool:
    from lirm.engine.synth.material_variety import VARIETY_VERSION

    meshes, _, paint = varied_meshes(np.random.default_rng([VARIETY_VERSION, seed]), VarietyConfig())
    return paint == "parts" and all(m.material.metallic_factor == 1.0 for m in meshes)
