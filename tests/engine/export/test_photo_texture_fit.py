"""Fitting an export's textures to photos (photo_texture_fit.py): through the renderer's G-buffer from
the photos' cameras, under the fitted lighting, the baked textures move toward what the photos show."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.cameras import Camera, look_at
from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.export.photo_texture_fit import (PhotoViews, PixelSamples, TextureFitConfig, fit_textures,
                                                  mesh_for_rendering, sample_photo_pixels)
from lirm.engine.export.texture_bake import BakedTextures
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.model.analytic_fields import MaterialPattern, SphereField
from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.procedural_environments import make_procedural_environment

SMALL = ExportConfig(mesh=MeshExtractionConfig(resolution=48, face_budget=3000), texture_size=128)


class _Dielectric(MaterialPattern):
    def metallic(self, p: torch.Tensor) -> torch.Tensor:
        return torch.zeros(p.shape[:-1], dtype=p.dtype, device=p.device)


CHECKER = _Dielectric(colour_a=(0.8, 0.25, 0.1), colour_b=(0.1, 0.3, 0.7), checker=0.3, roughness_range=(0.6, 0.6))
GREY = _Dielectric(colour_a=(0.4, 0.4, 0.4), colour_b=(0.4, 0.4, 0.4), roughness_range=(0.6, 0.6))


def _cameras(count: int = 8, size: int = 64) -> list[Camera]:
    return [Camera.from_fov(size, size, 40.0, look_at((2.5 * np.cos(a), 2.5 * np.sin(a), 1.2 * (-1) ** k), (0, 0, 0)))
            for k, a in enumerate(np.linspace(0.0, 2.0 * np.pi, count, endpoint=False))]


def test_fitting_recovers_the_albedo_the_pixels_were_shaded_with():
    """Without GL: pixels shaded from a known texture under a panorama; the fit, started from grey,
    brings the sampled texels to it and leaves unseen texels as they were."""
    g = torch.Generator().manual_seed(0)
    size, count = 16, 4000
    truth = torch.rand(size, size, 3, generator=g) * 0.8 + 0.1
    uv = torch.rand(count, 2, generator=g) * 0.5  # only the top-left quarter of the atlas is seen
    normal = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1)
    view = torch.nn.functional.normalize(normal + 0.3 * torch.randn(count, 3, generator=g), dim=-1)
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
    sampled = torch.nn.functional.grid_sample(truth.permute(2, 0, 1)[None], (uv * 2 - 1)[None, None], mode="bilinear",
                                              padding_mode="border", align_corners=False)[0, :, 0].T
    with torch.no_grad():
        colour = radiance_to_display_torch(shade(lighting, sampled, torch.full((count,), 0.5), torch.zeros(count), normal,
                                                 view).radiance)
    start = BakedTextures(np.full((size, size, 3), 0.4, np.float32), np.full((size, size), 0.5, np.float32),
                          np.zeros((size, size), np.float32), np.tile(np.float32([0, 0, 1]), (size, size, 1)),
                          np.ones((size, size), bool))
    with torch.no_grad():  # as the evaluation calls it: the fit makes its own gradients
        fitted, report = fit_textures(start, PixelSamples(uv, normal, view, colour), lighting,
                                      TextureFitConfig(steps=300, learning_rate=0.05, metal_search=False, register_heights=0))
    assert report.pixels == count and report.steps == 300 and report.loss_after < 0.2 * report.loss_before
    seen = (slice(1, size // 2 - 1), slice(1, size // 2 - 1))
    error_before = np.abs(start.base_color[seen] - truth.numpy()[seen]).mean()
    error_after = np.abs(fitted.base_color[seen] - truth.numpy()[seen]).mean()
    assert error_after < 0.25 * error_before, (error_before, error_after)
    np.testing.assert_allclose(fitted.base_color[-4:, -4:], 0.4, atol=1e-3)  # never seen: untouched
    np.testing.assert_array_equal(fitted.normal, start.normal)  # the normal map is not fitted
    # A random subset for captures of many large photos: seeded, and the whole set when it is small.
    samples = PixelSamples(uv, normal, view, colour)
    assert samples.subset(count) is samples
    part = samples.subset(500, seed=3)
    assert part.uv.shape == (500, 2) and torch.equal(part.colour, samples.subset(500, seed=3).colour)
    # Stopped before its first step, it keeps what it had.
    for search in (False, True):
        kept, report = fit_textures(start, PixelSamples(uv, normal, view, colour), lighting, TextureFitConfig(metal_search=search, register_heights=0),
                                    should_stop=lambda: True)
        assert report.stopped and report.steps == 0
        np.testing.assert_allclose(kept.base_color, start.base_color, atol=1e-3)


def test_the_metal_search_finds_metal_that_the_field_left_as_paint():
    """Without GL: an atlas whose left half is gold metal and right half yellow paint, each texel seen
    from many directions under the studio; the baked textures start as the field usually leaves them
    (grey paint, metallic 0). The plain fit, held to the field's metallic, keeps the gold as paint; the
    metal search makes the left half metal and leaves the right half paint, and explains the pixels
    better."""
    g = torch.Generator().manual_seed(1)
    size, count = 16, 12000
    uv = torch.rand(count, 2, generator=g)
    texel = (uv * size).long().clamp(max=size - 1)
    # One normal per texel (a texel is one surface point), spread over the sphere by its position.
    angle = (texel[:, 0].float() + 0.5) / size * 2.0 * np.pi
    height = (texel[:, 1].float() + 0.5) / size * 1.6 - 0.8
    normal = torch.stack([torch.cos(angle) * (1 - height**2).sqrt(), torch.sin(angle) * (1 - height**2).sqrt(), height], -1)
    view = torch.nn.functional.normalize(normal + 0.7 * torch.randn(count, 3, generator=g), dim=-1)
    facing = (view * normal).sum(-1) > 0.2
    uv, normal, view, metal_half = uv[facing], normal[facing], view[facing], uv[facing, 0] < 0.5
    gold, paint = torch.tensor([1.0, 0.76, 0.33]), torch.tensor([0.75, 0.55, 0.15])
    albedo = torch.where(metal_half[:, None], gold, paint)
    roughness = torch.where(metal_half, 0.3, 0.5)
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
    with torch.no_grad():
        colour = radiance_to_display_torch(shade(lighting, albedo, roughness, metal_half.float(), normal, view).radiance)
    start = BakedTextures(np.full((size, size, 3), 0.4, np.float32), np.full((size, size), 0.5, np.float32),
                          np.zeros((size, size), np.float32), np.tile(np.float32([0, 0, 1]), (size, size, 1)),
                          np.ones((size, size), bool))
    samples = PixelSamples(uv, normal, view, colour)
    left, right = (slice(2, size - 2), slice(1, size // 2 - 2)), (slice(2, size - 2), slice(size // 2 + 2, size - 1))
    with torch.no_grad():
        plain, plain_report = fit_textures(start, samples, lighting, TextureFitConfig(metal_search=False, register_heights=0))
        searched, report = fit_textures(start, samples, lighting, TextureFitConfig(metal_search=True, register_heights=0))
    assert plain_report.metal_share is None and "metal search" not in plain_report.summary()
    assert plain.metallic[left].mean() < 0.3, plain.metallic[left].mean()
    assert searched.metallic[left].mean() > 0.7 and searched.metallic[right].mean() < 0.3, (
        searched.metallic[left].mean(), searched.metallic[right].mean())
    assert 0.35 < report.metal_share < 0.65 and "metal search" in report.summary()
    assert report.loss_after < 0.7 * plain_report.loss_after, (report.loss_after, plain_report.loss_after)
    # With a footprint shaded per sub-sample, the search may shade one sub-sample of each pixel
    # (search_one_sample); pooled (the default), every fit shades each pixel once, its sub-samples'
    # reads and light averaged. Here every pixel's four sub-samples are alike, so all three choose
    # and fit as the search over all of them does.
    repeat = lambda t: t.repeat_interleave(4, 0)  # noqa: E731
    footprint = PixelSamples(repeat(uv), repeat(normal), repeat(view), colour, footprint=4).subset(4000)
    short = TextureFitConfig(search_steps=60, search_final_steps=60, register_heights=0, pooled_footprint=False)
    with torch.no_grad():
        full, full_report = fit_textures(start, footprint, lighting, replace(short, search_one_sample=False))
        one, one_report = fit_textures(start, footprint, lighting, replace(short, search_one_sample=True))
        pooled, pooled_report = fit_textures(start, footprint, lighting, replace(short, pooled_footprint=True))
    for report, fitted in ((one_report, one), (pooled_report, pooled)):
        assert report.metal_share == pytest.approx(full_report.metal_share, abs=0.01) and report.metal_share > 0.3
        np.testing.assert_allclose(fitted.metallic, full.metallic, atol=0.02)  # (float rounding, through Adam)
    np.testing.assert_allclose(pooled.base_color, full.base_color, atol=0.02)


def checker_sphere_photos(tmp_path, gl_context, renderer):
    """Photos (64 px, 8 views) of a checker sphere's export rendered under a 16 x 32 sky: the lighting,
    its environment, the cameras, the renders (`shots`, with their G-buffers) and the PhotoViews."""
    from types import SimpleNamespace

    lighting = PanoramaLighting.from_environment(make_procedural_environment("sky", width=128), height=16)
    environment = lighting.environment("sky 16 x 32")
    cameras = _cameras()
    truth = export_field(SphereField(0.5, pattern=CHECKER), tmp_path / "truth.glb", SMALL, context=gl_context)
    scene = renderer.upload([mesh_for_rendering(truth.uv_mesh, truth.textures)])
    lit = renderer.prepare_lighting(environment)
    try:
        shots = [renderer.render_view(scene, c, lit, RenderSettings(show_environment=False)) for c in cameras]
    finally:
        scene.release()
        lit.maps.release()
    photos = PhotoViews(cameras, np.stack([s.beauty for s in shots]), np.stack([s.mask for s in shots]))
    return SimpleNamespace(lighting=lighting, environment=environment, cameras=cameras, shots=shots, photos=photos)


def test_an_export_fitted_to_photos_of_a_checker_sphere_shows_the_checker(tmp_path, gl_context, renderer):
    """Photos of a checker sphere rendered by the renderer under an environment; a grey sphere's export,
    fitted to them under that environment, comes out close to the checker's albedo."""
    shoot = checker_sphere_photos(tmp_path, gl_context, renderer)
    lighting, environment, cameras, shots, photos = shoot.lighting, shoot.environment, shoot.cameras, shoot.shots, shoot.photos

    baked = export_field(SphereField(0.5, pattern=GREY), tmp_path / "baked.glb", SMALL, context=gl_context)
    assert baked.texture_fit is None  # no photos, no fit
    fitted = export_field(SphereField(0.5, pattern=GREY), tmp_path / "fitted.glb", SMALL, context=gl_context,
                          photos=photos, lighting=lighting)
    report = fitted.texture_fit
    assert report is not None and report.views == len(cameras) and report.pixels > 4000
    assert report.loss_after < 0.3 * report.loss_before, report.summary()
    assert "texture_fit" in fitted.seconds

    before, after = (exported_albedo_error(renderer, r.path, environment, cameras, shots) for r in (baked, fitted))
    assert after < 0.35 * before, (before, after)


def exported_albedo_error(renderer, path, environment, cameras, shots) -> float:
    """An exported .glb's albedo against the photos' true albedo (`shots`: the photos' renders), seen
    from the photos' cameras through the renderer's G-buffer."""
    from lirm.engine.assets.model_loader import load_model

    scene = renderer.upload(load_model(path).meshes)
    lit = renderer.prepare_lighting(environment)
    try:
        errors = []
        for camera, shot in zip(cameras, shots):
            out = renderer.render_view(scene, camera, lit, RenderSettings(show_environment=False))
            inside = (out.mask > 0.999) & (shot.mask > 0.999)
            errors.append(np.abs(out.albedo[inside] - shot.albedo[inside]).mean())
    finally:
        scene.release()
        lit.maps.release()
    return float(np.mean(errors))


def test_a_clipped_photo_pixel_is_only_a_lower_bound():
    """A photo value at the clip level says the surface was at least that bright: a texel shading
    brighter is left as it is (no error at all), a darker one is raised."""
    g = torch.Generator().manual_seed(1)
    count, size = 500, 8
    normal = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1)
    samples = PixelSamples(torch.rand(count, 2, generator=g), normal, normal, torch.ones(count, 3))  # all clipped white
    # A uniform light strong enough that albedo 0.9 shows above the clip level at every pixel.
    lighting = PanoramaLighting.from_environment(Environment(np.full((8, 16, 3), 40.0, np.float32)), height=8)

    def start(albedo: float) -> BakedTextures:
        return BakedTextures(np.full((size, size, 3), albedo, np.float32), np.full((size, size), 0.5, np.float32),
                             np.zeros((size, size), np.float32), np.tile(np.float32([0, 0, 1]), (size, size, 1)),
                             np.ones((size, size), bool))

    config = TextureFitConfig(steps=50, learning_rate=0.05, fit_materials=False, register_heights=0)
    kept, report = fit_textures(start(0.9), samples, lighting, config)
    assert report.loss_before == 0.0
    np.testing.assert_allclose(kept.base_color, 0.9, atol=2e-3)
    raised, _ = fit_textures(start(0.02), samples, lighting, config)
    assert raised.base_color.mean() > 0.1
    # Without the clip level a clipped pixel is an ordinary target: the dark texel is raised all the same.
    plain, _ = fit_textures(start(0.02), samples, lighting, replace(config, clip_level=None))
    assert plain.base_color.mean() > 0.1


def test_pixels_whose_normal_is_not_finite_are_left_out_of_the_samples(gl_context):
    """A triangle whose vertex normals are zero renders NaN normals (GLSL normalize(0)); its pixels are
    not samples, so no NaN reaches the shading, and the rest of the surface still is."""
    from lirm.renderer.mesh import MeshData

    positions = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], np.float32)
    uvs = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    healthy = np.tile(np.float32([0, 0, 1]), (4, 1))
    broken = healthy.copy()
    broken[[0, 2, 3]] = 0.0  # the second triangle's three normals
    camera = Camera.from_fov(32, 32, 40.0, look_at((0.0, -0.3, 2.0), (0, 0, 0), up=(0, 1, 0)))
    photos = PhotoViews([camera], np.full((1, 32, 32, 3), 0.5, np.float32), np.ones((1, 32, 32), np.float32))
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    whole = sample_photo_pixels(MeshData(positions, faces, normals=healthy, uvs=uvs), photos, gl_context)
    kept = sample_photo_pixels(MeshData(positions, faces, normals=broken, uvs=uvs), photos, gl_context)
    assert torch.isfinite(kept.normal).all() and torch.isfinite(kept.uv).all()
    assert 0.3 * len(whole.normal) < len(kept.normal) < 0.7 * len(whole.normal), (len(kept.normal), len(whole.normal))


def test_a_pixel_footprint_fit_recovers_detail_finer_than_a_pixel():
    """Without GL: stripes three texels wide seen by pixels three texels wide at every offset (as
    views see a surface at sub-pixel shifts), each pixel the mean of its footprint, as a sensor
    integrates. Shading each pixel at its 3 x 3 sub-samples and averaging recovers the stripes'
    contrast; one point per pixel (its centre) fits the texels to their neighbourhoods' means and
    keeps the blur."""
    g = torch.Generator().manual_seed(2)
    size, bright, dark = 18, 0.8, 0.15
    stripes = np.where(np.arange(size) % 6 < 3, bright, dark).astype(np.float32)
    truth = torch.from_numpy(np.repeat(np.repeat(stripes[None, :, None], size, 0), 3, 2))
    count = 4000
    corner = torch.randint(0, size - 2, (count, 2), generator=g).float() / size  # any texel offset
    grid = torch.stack(torch.meshgrid(torch.arange(3.0), torch.arange(3.0), indexing="ij"), -1).reshape(9, 2)
    uv = (corner[:, None] + (grid[None] + 0.5) / size).reshape(-1, 2)  # the 9 texel centres inside each pixel
    normal = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1).repeat_interleave(9, 0)
    view = normal.clone()
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
    sampled = torch.nn.functional.grid_sample(truth.permute(2, 0, 1)[None], (uv * 2 - 1)[None, None], mode="bilinear",
                                              padding_mode="border", align_corners=False)[0, :, 0].T
    with torch.no_grad():
        radiance = shade(lighting, sampled, torch.full((9 * count,), 0.6), torch.zeros(9 * count), normal, view).radiance
        colour = radiance_to_display_torch(radiance.reshape(count, 9, 3).mean(1))
    start = BakedTextures(np.full((size, size, 3), 0.45, np.float32), np.full((size, size), 0.6, np.float32),
                          np.zeros((size, size), np.float32), np.tile(np.float32([0, 0, 1]), (size, size, 1)),
                          np.ones((size, size), bool))
    config = TextureFitConfig(steps=400, learning_rate=0.05, metal_search=False, fit_materials=False, register_heights=0)
    footprint = PixelSamples(uv, normal, view, colour, footprint=9)
    centre = PixelSamples(uv[4::9], normal[::9], view[::9], colour)  # one point at each pixel's centre
    assert footprint.pixels == centre.pixels == count and torch.equal(footprint.pixel_uv, uv[::9])
    part = footprint.subset(100, seed=1)
    assert part.pixels == 100 and part.uv.shape == (900, 2) and torch.equal(part.pixel_uv, part.uv[::9])
    with torch.no_grad():
        fine, fine_report = fit_textures(start, footprint, lighting, config)
        coarse, _ = fit_textures(start, centre, lighting, config)
    assert fine_report.pixels == count
    inner = slice(3, size - 3)  # away from the atlas border, which fewer pixels cover
    is_bright = np.arange(size)[inner] % 6 < 3

    def contrast(textures: BakedTextures) -> float:
        columns = textures.base_color[inner, inner, 0].mean(0)
        return float(columns[is_bright].mean() - columns[~is_bright].mean())

    truth_contrast = bright - dark
    assert contrast(fine) > 0.85 * truth_contrast and contrast(coarse) < 0.7 * truth_contrast, (contrast(fine), contrast(coarse))


def test_footprint_samples_group_each_pixels_sub_samples(tmp_path, gl_context):
    """Rasterised at 2 x 2 sub-samples per photo pixel: 4 rows per pixel, in the pixel's footprint,
    and no more pixels than one sample each gives (a pixel needs all of its sub-samples covered)."""
    cameras = _cameras(count=2, size=32)
    export = export_field(SphereField(0.5, pattern=CHECKER), tmp_path / "sphere.glb", SMALL, context=gl_context)
    mesh = mesh_for_rendering(export.uv_mesh, export.textures)
    photos = PhotoViews(cameras, np.zeros((2, 32, 32, 3), np.float32), np.ones((2, 32, 32), np.float32))
    one = sample_photo_pixels(mesh, photos, gl_context)
    four = sample_photo_pixels(mesh, photos, gl_context, footprint=2)
    assert four.footprint == 4 and four.uv.shape[0] == 4 * four.pixels and four.normal.shape[0] == 4 * four.pixels
    assert 0.8 * one.pixels < four.pixels <= one.pixels
    # Where each pixel lies in its photo is recorded only when asked (the registration's input).
    assert one.sources is None and four.sources is None
    located = sample_photo_pixels(mesh, photos, gl_context, footprint=2, with_sources=True)
    assert located.sources is not None and len(located.sources.xy) == located.pixels == four.pixels
    # A pixel's sub-samples look along nearly the same ray and land close together in the atlas.
    spread = (four.view.reshape(-1, 4, 3) - four.view.reshape(-1, 4, 3).mean(1, keepdim=True)).norm(dim=-1).max()
    assert spread < 0.05


def test_each_pixels_parallax_is_how_far_its_point_moves_when_raised_along_the_normal(gl_context):
    """A plane seen face on from 2 units away: raising a point toward the camera magnifies it about
    the image centre, so a pixel at (x, y) moves by ((x, y) - centre) / 2 per unit of height
    (surface_heights.py reads the photos there)."""
    from lirm.renderer.mesh import MeshData

    positions = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    mesh = MeshData(positions, np.array([[0, 1, 2], [0, 2, 3]]), normals=np.tile(np.float32([0, 0, 1]), (4, 1)),
                    uvs=np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32))
    camera = Camera.from_fov(32, 32, 40.0, look_at((0.0, 0.0, 2.0), (0, 0, 0), up=(0, 1, 0)))
    photos = PhotoViews([camera], np.full((1, 32, 32, 3), 0.5, np.float32), np.ones((1, 32, 32), np.float32))
    for footprint in (1, 2):
        sources = sample_photo_pixels(mesh, photos, gl_context, footprint=footprint, with_sources=True).sources
        assert len(sources.xy) > 500
        expected = (sources.xy - torch.tensor([camera.cx, camera.cy], dtype=torch.float32)) / 2.0
        assert float((sources.parallax - expected).abs().max()) < 0.05, footprint
