"""The glTF sample models in ../shared/data render correctly (loader + renderer together)."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.assets.model_loader import load_model
from lirm.engine.cameras import Camera, look_at
from lirm.engine.orbit_render import OrbitRenderConfig, normalizing_transform, orbit_for
from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.procedural_environments import make_procedural_environment
from lirm.renderer.tonemap import srgb_to_linear

MODELS = [
    "DamagedHelmet_gltf/DamagedHelmet.gltf", "Avocado_tex256.glb", "WaterBottle_tex256.glb", "NormalTangentTest.glb",
    "ClearcoatWicker.glb", "pmndrs_bunny_untextured.glb", "pmndrs_suzi_untextured.glb",
]


@pytest.fixture(scope="module")
def studio(renderer):
    lighting = renderer.prepare_lighting(make_procedural_environment("studio", width=256))
    yield lighting
    lighting.maps.release()


def _render(renderer, model, camera, lighting, **settings):
    scene = renderer.upload(model.meshes, normalizing_transform(model.bounds))
    try:
        return renderer.render_view(scene, camera, lighting, RenderSettings(**settings))
    finally:
        scene.release()


def _bilinear_linear(texture: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup with REPEAT wrap in an sRGB texture decoded to linear first."""
    h, w = texture.shape[:2]
    lin = srgb_to_linear(texture[:, :, :3] / 255.0)
    x = uv[:, 0] * w - 0.5
    y = uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, x1, y0, y1 = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
    return (lin[y0, x0] * (1 - fx) + lin[y0, x1] * fx) * (1 - fy) + (lin[y1, x0] * (1 - fx) + lin[y1, x1] * fx) * fy


@pytest.mark.parametrize("name", MODELS)
def test_every_sample_model_renders(renderer, studio, shared_data, name):
    model = load_model(shared_data / "pbr_models" / name)
    camera = orbit_for(OrbitRenderConfig(views=1, width=96, height=96, start_azimuth_deg=-30))[0]
    out = _render(renderer, model, camera, studio)
    assert 0.05 < out.mask.mean() < 0.95, "the model should sit inside the frame"
    for channel in (out.radiance, out.albedo, out.normal, out.beauty):
        assert np.isfinite(channel).all()
    assert out.radiance[out.mask > 0].mean() > 0.01


@pytest.mark.parametrize("name,texture_size", [("Avocado_tex256.glb", 256), ("WaterBottle_tex256.glb", 256)])
def test_gbuffer_albedo_equals_the_models_texture_lookup(renderer, studio, shared_data, name, texture_size):
    model = load_model(shared_data / "pbr_models" / name)
    mesh = model.meshes[0]
    assert mesh.material.base_color_texture.shape[0] == texture_size
    # Close enough that the texture is magnified (one texel spans more than one pixel): level 0 only.
    camera = Camera.from_fov(320, 320, 25.0, look_at((0, -2.2, 0.3), (0, 0, 0)))
    out = _render(renderer, model, camera, studio)
    inside = out.mask > 0.999
    # Keep pixels away from silhouettes, where neighbouring texels may belong to other UV charts.
    core = inside & np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & np.roll(inside, 1, 1) & np.roll(inside, -1, 1)
    assert core.sum() > 5000
    factor = np.asarray(mesh.material.base_color_factor[:3])
    expected = _bilinear_linear(mesh.material.base_color_texture, out.uv[core]) * factor
    error = np.abs(out.albedo[core] - expected)
    assert np.median(error) < 0.004
    assert np.percentile(error, 99) < 0.03  # UV seams inside the silhouette


def test_damaged_helmet_renders_its_textures_and_emission(renderer, shared_data):
    model = load_model(shared_data / "pbr_models" / "DamagedHelmet_gltf" / "DamagedHelmet.gltf")
    material = model.meshes[0].material
    camera = orbit_for(OrbitRenderConfig(views=1, width=256, height=256, elevation_deg=0))[0]  # the visor side
    dark = renderer.prepare_lighting(Environment(np.zeros((16, 32, 3), np.float32)))
    try:
        out = _render(renderer, model, camera, dark)
    finally:
        dark.maps.release()
    # In a black environment only the emissive texture (the visor's display) lights anything.
    glowing = out.radiance.max(axis=2) > 0.05
    assert 0.001 < glowing.mean() < 0.2
    assert model.meshes[0].material.emissive_factor == pytest.approx((1.0, 1.0, 1.0))
    # Metallic and roughness come from B and G of the metallicRoughness texture: the helmet is mostly
    # metal with varied roughness, so the two channels must differ.
    inside = out.mask > 0.99
    assert out.metallic[inside].mean() > 0.5
    assert np.abs(out.metallic[inside] - out.roughness[inside]).mean() > 0.1
    assert material.metallic_roughness_texture is not None


def test_normal_tangent_test_bumps_all_face_the_same_way(renderer, studio, shared_data):
    """NormalTangentTest's hemispheres use every UV orientation; with correct tangent frames they all
    shade as bumps: the normal's rightward part grows to the right and its upward part shrinks
    downward. A flipped green channel or bitangent sign breaks this on half of them (measured ~59%)."""
    model = load_model(shared_data / "pbr_models" / "NormalTangentTest.glb")
    camera = orbit_for(OrbitRenderConfig(views=1, width=384, height=384, elevation_deg=0))[0]
    out = _render(renderer, model, camera, studio)
    right, up, toward = out.normal @ camera.right, out.normal @ camera.up, -(out.normal @ camera.forward)
    tilted = (out.mask > 0.5) & (toward < 0.97)
    hx = tilted[:, 2:] & tilted[:, :-2] & tilted[:, 1:-1]
    hy = tilted[2:, :] & tilted[:-2, :] & tilted[1:-1, :]
    assert hx.sum() > 3000
    assert ((right[:, 2:] - right[:, :-2])[hx] > 0).mean() > 0.85
    assert ((up[2:, :] - up[:-2, :])[hy] < 0).mean() > 0.85


def test_clearcoat_model_renders_its_base_layer_with_a_warning(renderer, studio, shared_data):
    model = load_model(shared_data / "pbr_models" / "ClearcoatWicker.glb")
    assert any("KHR_materials_clearcoat" in w for w in model.warnings)
    assert "KHR_materials_clearcoat" in model.meshes[0].material.ignored_extensions
    camera = orbit_for(OrbitRenderConfig(views=1, width=96, height=96))[0]
    out = _render(renderer, model, camera, studio)
    assert out.mask.mean() > 0.2
