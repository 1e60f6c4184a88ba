"""Registering the photos before the texture fit (photo_registration.py, TextureFitConfig.register_grid):
photos that see the texture displaced, each by its own small shift, are moved back onto it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.export.photo_registration import PhotoSources, ViewWarps, photo_sources, read_photos
from lirm.engine.export.photo_texture_fit import PixelSamples, TextureFitConfig, fit_textures
from lirm.engine.export.texture_bake import BakedTextures
from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.renderer.procedural_environments import make_procedural_environment


def test_reading_the_photos_unmoved_gives_each_pixels_own_colour():
    rng = np.random.default_rng(0)
    images = rng.random((3, 10, 12, 3)).astype(np.float32)
    masks = rng.random((3, 10, 12)).astype(np.float32)
    rows, columns = np.nonzero(masks[1] > 0.5)
    sources = photo_sources([np.zeros((0, 2)), np.stack([columns + 0.5, rows + 0.5], -1), np.zeros((0, 2))], images, masks)
    colour, alpha = read_photos(sources)
    np.testing.assert_allclose(colour.numpy(), images[1][masks[1] > 0.5], atol=1e-6)
    np.testing.assert_allclose(alpha.numpy(), masks[1][masks[1] > 0.5], atol=1e-6)


def test_a_photos_warp_moves_only_its_own_pixels():
    """The lattices sit side by side in one tensor; one photo's nodes never reach the next photo's pixels,
    and a read stays inside its own photo however far it is pushed."""
    images = np.zeros((2, 8, 8, 3), np.float32)
    images[1] = 1.0
    xy = np.stack(np.meshgrid(np.arange(8) + 0.5, np.arange(8) + 0.5), -1).reshape(-1, 2)
    sources = photo_sources([xy, xy], images, np.ones((2, 8, 8), np.float32))
    warps = ViewWarps(views=2, grid=3, max_shift=20.0)
    with torch.no_grad():
        warps.raw[..., :3] = 15.0  # the first photo's nodes only: every one of its pixels pushed right
        offsets = warps.offsets(sources)
    first = sources.view == 0
    assert torch.allclose(offsets[first], offsets[first][:1]) and float(offsets[first][0, 0]) > 10.0
    assert float(offsets[~first].abs().max()) == 0.0
    colour, _ = read_photos(sources, offsets)
    assert float(colour[first].max()) == 0.0  # pushed to its own right edge, not into the second photo


def _shifted_views(shifts: np.ndarray, size: int = 48, period: float = 6.0, heights=None):
    """Photos of a flat sinusoid-patterned texture seen face on, one texel per pixel, each displaced by
    its own shift (pixels); the samples map each pixel to the texel it would see without the shift
    (as a reconstruction a little off would). With `heights` (a function of the texture coordinates
    (x, y) / size), each shift is instead the photo's parallax: the texture truly lies that high
    above the samples' surface, and a photo shows the texel at (x, y) moved by height x parallax (the
    samples record each pixel's parallax)."""
    lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
    normal = torch.tensor([[0.0, 0.0, 1.0]])

    def albedo(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        wave = 0.5 + 0.35 * np.sin(2 * np.pi * x / period) * np.cos(2 * np.pi * y / (1.5 * period))
        return np.stack([wave, 0.6 - 0.4 * (wave - 0.5), np.full_like(wave, 0.3)], -1).astype(np.float32)

    def display(albedos: np.ndarray) -> np.ndarray:
        flat = torch.from_numpy(albedos.reshape(-1, 3))
        n = normal.expand(len(flat), 3)
        with torch.no_grad():
            out = radiance_to_display_torch(shade(lighting, flat, torch.full((len(flat),), 0.6), torch.zeros(len(flat)), n, n).radiance)
        return out.numpy().reshape(albedos.shape)

    centre = np.arange(size) + 0.5
    x, y = np.meshgrid(centre, centre)
    lift = np.ones_like(x) if heights is None else heights(x / size, y / size)
    images = np.stack([display(albedo(x - lift * dx, y - lift * dy)) for dx, dy in shifts])
    inner = (x > 6) & (x < size - 6) & (y > 6) & (y < size - 6)
    xy = np.stack([x[inner], y[inner]], -1)
    parallax = None if heights is None else [np.tile(shift, (len(xy), 1)) for shift in shifts]
    sources = photo_sources([xy] * len(shifts), images, np.ones(images.shape[:3], np.float32), parallax)
    count = len(sources.xy)
    uv = sources.xy / size
    n = normal.expand(count, 3).contiguous()
    colour, _ = read_photos(sources)
    samples = PixelSamples(uv, n, n.clone(), colour, 1, sources)
    truth = albedo(x, y)
    start = BakedTextures(np.full((size, size, 3), 0.45, np.float32), np.full((size, size), 0.6, np.float32),
                          np.zeros((size, size), np.float32), np.tile(np.float32([0, 0, 1]), (size, size, 1)),
                          np.ones((size, size), bool))
    return samples, lighting, start, truth, inner


def test_registration_undoes_each_photos_shift_and_keeps_the_textures_detail():
    shifts = np.array([[1.2, -0.6], [-1.0, 0.9], [0.4, 1.3], [-0.6, -1.6]], np.float32)
    shifts -= shifts.mean(0)  # a shift all photos share is the texture's, not theirs
    samples, lighting, start, truth, inner = _shifted_views(shifts)
    plain = TextureFitConfig(steps=300, learning_rate=0.05, metal_search=False, fit_materials=False, register_heights=0)
    registered = TextureFitConfig(steps=300, learning_rate=0.05, metal_search=False, fit_materials=False, register_grid=2,
                                  register_steps=300, register_learning_rate=0.05)
    with torch.no_grad():  # as the evaluation calls it: the fit makes its own gradients
        blurred, plain_report = fit_textures(start, samples, lighting, plain, views=len(shifts))
        sharp, report = fit_textures(start, samples, lighting, registered, views=len(shifts))
    assert plain_report.registration_shift is None
    assert report.registration_shift == pytest.approx(float(np.linalg.norm(shifts, axis=1).mean()), abs=0.25)
    assert "photos registered" in report.summary() and report.steps == 600

    def error(textures: BakedTextures) -> float:
        return float(np.abs(textures.base_color - truth)[inner].mean())

    assert error(sharp) < 0.5 * error(blurred), (error(sharp), error(blurred))
    assert report.loss_after < 0.5 * plain_report.loss_after


def test_registration_needs_each_pixels_place_in_its_photo():
    samples, lighting, start, _, _ = _shifted_views(np.zeros((2, 2), np.float32))
    bare = PixelSamples(samples.uv, samples.normal, samples.view, samples.colour)
    with pytest.raises(ValueError, match="place in its photo"):
        fit_textures(start, bare, lighting, TextureFitConfig(steps=5, metal_search=False, register_grid=2, register_steps=5))
    with pytest.raises(ValueError, match="register_grid"):
        TextureFitConfig(register_grid=1)
    assert isinstance(samples.subset(10).sources, PhotoSources) and len(samples.subset(10).sources.xy) == 10


def test_heights_over_the_surface_undo_a_parallax_that_changes_over_it():
    """The texture lies above the samples' surface by a height that varies across it (one bump), so
    each photo sees it displaced by height x its own parallax: no smooth warp per photo undoes that,
    one height map shared by the photos does (surface_heights.py)."""
    def bump(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return 1.2 * np.cos(np.pi * (u - 0.5)) * np.cos(np.pi * (v - 0.5)) - 0.4

    parallax = np.array([[1.5, 0.0], [-1.5, 0.0], [0.0, 1.5], [0.0, -1.5]], np.float32)
    samples, lighting, start, truth, inner = _shifted_views(parallax, heights=bump)
    plain = TextureFitConfig(steps=300, learning_rate=0.05, metal_search=False, fit_materials=False, register_heights=0)
    lifted = TextureFitConfig(steps=300, learning_rate=0.05, metal_search=False, fit_materials=False, register_heights=8,
                              register_max_height=2.0, register_steps=300, height_learning_rate=0.05, height_smooth=0.01)
    with torch.no_grad():
        blurred, _ = fit_textures(start, samples, lighting, plain, views=len(parallax))
        sharp, report = fit_textures(start, samples, lighting, lifted, views=len(parallax))
    assert "photos registered" in report.summary() and report.registration_shift > 0.5

    def error(textures: BakedTextures) -> float:
        return float(np.abs(textures.base_color - truth)[inner].mean())

    assert error(sharp) < 0.5 * error(blurred), (error(sharp), error(blurred))
