"""Shading and G-buffer checks with analytic scenes (llvmpipe through EGL in CI)."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at
from lirm.renderer.brdf_reference import split_sum_terms
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.primitives import quad, uv_sphere
from lirm.renderer.tonemap import srgb_to_linear, tonemap

L = 0.7


@pytest.fixture(scope="module")
def uniform_lighting(renderer):
    lighting = renderer.prepare_lighting(Environment(np.full((64, 128, 3), L, np.float32), name="uniform"))
    yield lighting
    lighting.maps.release()


def front_camera(size: int = 128, distance: float = 4.0, fov: float = 40.0) -> Camera:
    return Camera.from_fov(size, size, fov, look_at((0, -distance, 0), (0, 0, 0)))


def top_camera(size: int = 128, distance: float = 3.0, fov: float = 30.0) -> Camera:
    """Looks down -Z with image x along +x and image y along -y: the quad's uv layout."""
    return Camera.from_fov(size, size, fov, look_at((0, 0, distance), (0, 0, 0), up=(0, 1, 0)))


def render_one(renderer, meshes, camera, lighting, **settings):
    scene = renderer.upload(meshes)
    try:
        return renderer.render_view(scene, camera, lighting, RenderSettings(**settings))
    finally:
        scene.release()


def test_white_lambertian_sphere_reflects_the_constant_environment(renderer, uniform_lighting):
    white = PBRMaterial(base_color_factor=(1, 1, 1, 1), metallic_factor=0.0, roughness_factor=1.0)
    out = render_one(renderer, [uv_sphere(material=white)], front_camera(), uniform_lighting)
    inside = out.mask > 0.99
    assert inside.sum() > 2000
    np.testing.assert_allclose(out.radiance[inside], L, rtol=0.01)


def test_environment_intensity_scales_radiance(renderer, uniform_lighting):
    white = PBRMaterial(metallic_factor=0.0, roughness_factor=1.0)
    uniform_lighting.intensity_ev = 1.0
    try:
        out = render_one(renderer, [uv_sphere(material=white)], front_camera(), uniform_lighting)
    finally:
        uniform_lighting.intensity_ev = 0.0
    np.testing.assert_allclose(out.radiance[out.mask > 0.99], 2 * L, rtol=0.01)


@pytest.mark.parametrize("roughness", [0.25, 0.5, 0.75, 1.0])
def test_furnace_rough_white_metal(renderer, uniform_lighting, roughness):
    metal = PBRMaterial(base_color_factor=(1, 1, 1, 1), metallic_factor=1.0, roughness_factor=roughness)
    camera = front_camera()
    # With multiple-scattering compensation a white metal loses no energy.
    out = render_one(renderer, [uv_sphere(material=metal)], camera, uniform_lighting)
    inside = out.mask > 0.99
    np.testing.assert_allclose(out.radiance[inside], L, rtol=0.015)
    # Single scattering alone follows the GGX-Smith directional albedo (the split sum's known loss):
    # at the sphere's centre N.V ~ 1, so radiance = L * (A + B) for F0 = 1.
    single = render_one(renderer, [uv_sphere(material=metal)], camera, uniform_lighting, multiple_scattering=False)
    centre = single.radiance[62:66, 62:66].mean()
    n_dot_v = float(-single.normal[64, 64] @ camera.forward)
    a, b = split_sum_terms(n_dot_v, roughness)
    assert centre == pytest.approx(L * (a + b), rel=0.02)
    assert centre <= L * 1.001


def test_gbuffer_material_channels_and_texture_lookup(renderer, uniform_lighting):
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, size=(16, 16, 3), dtype=np.uint8)
    mr = np.zeros((16, 16, 3), np.uint8)
    mr[:, :, 1] = np.linspace(0, 255, 16, dtype=np.uint8)[None, :]  # roughness varies along u
    mr[:, :, 2] = np.linspace(255, 0, 16, dtype=np.uint8)[:, None]  # metallic varies along v
    material = PBRMaterial(base_color_texture=base, metallic_roughness_texture=mr, metallic_factor=1.0, roughness_factor=1.0)
    camera = top_camera(size=96)
    out = render_one(renderer, [quad(material=material)], camera, uniform_lighting)
    inside = out.mask > 0.99
    assert inside.mean() > 0.5
    # Each pixel's uv, looked up bilinearly (texel centres at (i + 0.5) / 16, glTF's default REPEAT
    # wrap) in the texture decoded to linear before filtering, as OpenGL's sRGB textures do.
    uv = out.uv[inside]
    x = uv[:, 0] * 16 - 0.5
    y = uv[:, 1] * 16 - 0.5
    x0 = np.floor(x).astype(int)
    y0 = np.floor(y).astype(int)
    fx = (x - x0)[:, None]
    fy = (y - y0)[:, None]
    x0, x1, y0, y1 = x0 % 16, (x0 + 1) % 16, y0 % 16, (y0 + 1) % 16

    def bilinear(tex):
        t = tex.astype(np.float64)
        return (t[y0, x0] * (1 - fx) + t[y0, x1] * fx) * (1 - fy) + (t[y1, x0] * (1 - fx) + t[y1, x1] * fx) * fy

    expected_albedo = bilinear(srgb_to_linear(base / 255.0))
    np.testing.assert_allclose(out.albedo[inside], expected_albedo, atol=0.01)
    expected_mr = bilinear(mr / 255.0)
    np.testing.assert_allclose(out.roughness[inside], expected_mr[:, 1], atol=0.01)  # G = roughness
    np.testing.assert_allclose(out.metallic[inside], expected_mr[:, 2], atol=0.01)  # B = metallic
    # The quad's uv layout seen from above: u grows to the right, v grows downward in the image.
    assert out.uv[48, 80, 0] > out.uv[48, 16, 0]
    assert out.uv[80, 48, 1] > out.uv[16, 48, 1]


def test_depth_normal_and_projection_agree_with_the_camera(renderer, uniform_lighting):
    camera = Camera.from_fov(160, 120, 50.0, look_at((1.5, -3.0, 1.0), (0.2, 0.1, 0.0)))
    center = np.array([0.3, 0.2, 0.1])
    out = render_one(renderer, [uv_sphere(radius=0.15, center=center)], camera, uniform_lighting, supersample=2)
    ys, xs = np.nonzero(out.mask > 0)
    weights = out.mask[ys, xs]
    centroid = np.array([np.sum((xs + 0.5) * weights), np.sum((ys + 0.5) * weights)]) / weights.sum()
    projected, depth = camera.project(center)
    np.testing.assert_allclose(centroid, projected, atol=0.5)  # pixel-centre convention end to end
    # Depth along the optical axis and world normals of the visible surface.
    full = out.mask > 0.999
    origins, dirs = camera.pixel_rays()
    hit_dist = out.depth[full] / (dirs[full] @ camera.forward)
    points = origins[full] + dirs[full] * hit_dist[:, None]
    np.testing.assert_allclose(np.linalg.norm(points - center, axis=1), 0.15, atol=0.003)
    expected_normals = (points - center) / np.linalg.norm(points - center, axis=1, keepdims=True)
    assert np.mean(np.sum(expected_normals * out.normal[full], axis=1)) > 0.999


def test_tonemapped_beauty_matches_the_numpy_reference(renderer, uniform_lighting):
    colour = PBRMaterial(base_color_factor=(0.9, 0.4, 0.1, 1), metallic_factor=0.0, roughness_factor=0.6)
    for ev in (-1.0, 0.0, 1.5):
        out = render_one(renderer, [uv_sphere(material=colour)], front_camera(), uniform_lighting, exposure_ev=ev)
        inside = out.mask > 0.99
        expected = tonemap(out.radiance[inside], exposure_ev=ev)
        np.testing.assert_allclose(out.beauty[inside], expected, atol=1.5 / 255)


def test_background_is_the_environment_seen_through_each_pixel(renderer):
    env = Environment(np.ones((128, 256, 3), np.float32))
    dirs, _ = env.texel_directions()
    env.radiance = (1.0 + dirs).astype(np.float32)
    lighting = renderer.prepare_lighting(env, rotation_deg=30.0)
    try:
        camera = Camera.from_fov(64, 48, 70.0, look_at((0, 0, 0), (1.0, 2.0, 0.5)))
        tiny = uv_sphere(radius=1e-3, center=(50, 50, 50))  # out of view: the image is all background
        out = render_one(renderer, [tiny], camera, lighting)
        _, ray_dirs = camera.pixel_rays()
        # Rotating the environment by +30 degrees about +Z: what was at d is now at Rz(30) d.
        a = np.deg2rad(-30.0)
        rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
        expected = 1.0 + ray_dirs @ rz.T
        np.testing.assert_allclose(out.radiance, expected, atol=0.03)
        assert out.mask.max() == 0.0
        hidden = render_one(renderer, [tiny], camera, lighting, show_environment=False)
        assert hidden.radiance.max() == 0.0
    finally:
        lighting.maps.release()


def test_environment_rotation_equals_rolling_the_panorama(renderer):
    rng = np.random.default_rng(1)
    radiance = np.repeat(np.repeat(rng.random((8, 16, 3)), 16, axis=0), 16, axis=1).astype(np.float32)
    sphere = [uv_sphere(material=PBRMaterial(metallic_factor=1.0, roughness_factor=0.3))]
    rotated = renderer.prepare_lighting(Environment(radiance), rotation_deg=90.0)
    rolled = renderer.prepare_lighting(Environment(np.roll(radiance, -radiance.shape[1] // 4, axis=1)))
    try:
        a = render_one(renderer, sphere, front_camera(), rotated)
        b = render_one(renderer, sphere, front_camera(), rolled)
        np.testing.assert_allclose(a.radiance, b.radiance, atol=0.02)
    finally:
        rotated.maps.release()
        rolled.maps.release()


def test_normal_map_tilts_the_shading_normal_along_the_tangent_frame(renderer, uniform_lighting):
    # Tangent-space normal (0.6, 0, 0.8) leans toward +u; (0, 0.6, 0.8) leans toward +Y of the image,
    # i.e. toward decreasing v, which on this quad is world +y.
    for tangent_normal, expected in [((0.6, 0.0, 0.8), (0.6, 0.0, 0.8)), ((0.0, 0.6, 0.8), (0.0, 0.6, 0.8))]:
        texel = np.round((np.array(tangent_normal) * 0.5 + 0.5) * 255).astype(np.uint8)
        material = PBRMaterial(normal_texture=np.tile(texel, (4, 4, 1)))
        out = render_one(renderer, [quad(material=material)], top_camera(size=64), uniform_lighting)
        n = out.normal[out.mask > 0.99].mean(axis=0)
        np.testing.assert_allclose(n / np.linalg.norm(n), np.array(expected), atol=0.01)


def test_emissive_occlusion_and_vertex_colours(renderer):
    dark = renderer.prepare_lighting(Environment(np.zeros((32, 64, 3), np.float32)))
    lit = renderer.prepare_lighting(Environment(np.full((32, 64, 3), L, np.float32)))
    try:
        glow = PBRMaterial(base_color_factor=(0, 0, 0, 1), emissive_factor=(1.0, 0.5, 0.25),
                           emissive_texture=np.full((2, 2, 3), 255, np.uint8))
        out = render_one(renderer, [quad(material=glow)], top_camera(size=32), dark)
        np.testing.assert_allclose(out.radiance[out.mask > 0.99], np.broadcast_to([1.0, 0.5, 0.25], (int((out.mask > 0.99).sum()), 3)), atol=1e-3)

        occluded = PBRMaterial(metallic_factor=0.0, roughness_factor=1.0, occlusion_texture=np.full((2, 2, 1), 128, np.uint8))
        out = render_one(renderer, [uv_sphere(material=occluded)], front_camera(size=64), lit)
        np.testing.assert_allclose(out.radiance[out.mask > 0.99], L * srgb_to_linear(1.0) * 128 / 255, rtol=0.02)
        np.testing.assert_allclose(out.occlusion[out.mask > 0.99], 128 / 255, atol=0.005)

        sphere = uv_sphere(material=PBRMaterial(metallic_factor=0.0))
        sphere.colors = np.tile(np.array([[0.2, 0.5, 1.0, 1.0]], np.float32), (len(sphere.positions), 1))
        out = render_one(renderer, [sphere], front_camera(size=64), lit)
        inside = out.mask > 0.99
        np.testing.assert_allclose(out.albedo[inside], np.broadcast_to([0.2, 0.5, 1.0], (int(inside.sum()), 3)), atol=0.005)
    finally:
        dark.maps.release()
        lit.maps.release()


def test_supersampling_gives_fractional_coverage_on_edges_only(renderer, uniform_lighting):
    sharp = render_one(renderer, [uv_sphere()], front_camera(size=64), uniform_lighting)
    smooth = render_one(renderer, [uv_sphere()], front_camera(size=64), uniform_lighting, supersample=3)
    assert set(np.unique(sharp.mask)) <= {0.0, 1.0}
    edge = (smooth.mask > 0.05) & (smooth.mask < 0.95)
    assert edge.sum() > 50
    assert abs(smooth.mask.sum() - sharp.mask.sum()) < 0.03 * sharp.mask.sum()
    np.testing.assert_allclose(smooth.albedo[smooth.mask > 0.99], 1.0, atol=1e-3)


def test_back_faces_are_culled_unless_double_sided(renderer, uniform_lighting):
    below = Camera.from_fov(32, 32, 30.0, look_at((0, 0, -3), (0, 0, 0), up=(0, 1, 0)))
    single = render_one(renderer, [quad()], below, uniform_lighting)
    double = render_one(renderer, [quad(material=PBRMaterial(double_sided=True))], below, uniform_lighting)
    assert single.mask.max() == 0.0
    assert double.mask.mean() > 0.5
    # Seen from behind, a double-sided surface shades with the flipped normal (facing the camera).
    np.testing.assert_allclose(double.normal[double.mask > 0.99].mean(axis=0), np.array([0.0, 0.0, -1.0]), atol=1e-3)


def test_rendering_survives_another_headless_context_made_and_released(renderer, uniform_lighting):
    """Synthetic data and benchmarks make their own contexts; EGL then leaves that one current and
    the renderer must make its own current again rather than draw nowhere."""
    from lirm.renderer.context import create_headless_context

    other = create_headless_context()
    other.release()
    out = render_one(renderer, [uv_sphere(material=PBRMaterial(base_color_factor=(1.0, 1.0, 1.0, 1.0)))], front_camera(), uniform_lighting)
    assert (out.mask > 0.5).sum() > 2000


@pytest.mark.parametrize("factor", [2, 3])
def test_supersampled_render_is_resolved_on_the_gpu_as_the_numpy_reference_does(renderer, factor):
    from lirm.renderer.pbr_renderer import downsample_reference

    rng = np.random.default_rng(factor)
    panorama = rng.uniform(0.05, 3.0, size=(32, 64, 3)).astype(np.float32)  # lighting that varies per pixel
    lighting = renderer.prepare_lighting(Environment(panorama, name="noise"))
    base = rng.integers(0, 256, size=(16, 16, 3), dtype=np.uint8)
    mr = rng.integers(0, 256, size=(16, 16, 3), dtype=np.uint8)
    meshes = [uv_sphere(radius=0.6, material=PBRMaterial(base_color_texture=base, metallic_roughness_texture=mr)),
              uv_sphere(radius=0.4, center=(0.5, -0.5, 0.3), material=PBRMaterial(base_color_factor=(0.9, 0.2, 0.1, 1.0),
                                                                                  metallic_factor=0.0, roughness_factor=0.3))]
    camera = front_camera(size=48, distance=3.0)
    big = Camera.from_fov(48 * factor, 48 * factor, 40.0, camera.c2w)
    try:
        resolved = render_one(renderer, meshes, camera, lighting, supersample=factor)
        reference = downsample_reference(render_one(renderer, meshes, big, lighting), factor)
    finally:
        lighting.maps.release()
    edge = (reference.mask > 0) & (reference.mask < 1)
    assert edge.sum() > 30 and (reference.mask == 1).sum() > 300  # edges and interiors both tested
    for name in ("beauty", "radiance", "albedo", "roughness", "metallic", "occlusion", "normal", "depth", "mask", "uv"):
        np.testing.assert_allclose(getattr(resolved, name), getattr(reference, name), atol=2e-5, rtol=1e-5, err_msg=name)
