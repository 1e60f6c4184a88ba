"""The texture fit at the photos' resolution (fit_resolution.py): how finely the photos sample the
atlas, the size chosen from it, the fit's change carried back to the export's size, and an export
whose texture is far finer than its photos fitted better that way than texel for texel."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.export.fit_resolution import (averaged_down, carried_up, fit_size_for, texels_per_photo_pixel)
from lirm.engine.export.texture_bake import BakedTextures


def _pixel_grid(pixels: int, side_uv: float, k: int = 2) -> torch.Tensor:
    """uv rows of `pixels` photo pixels of `side_uv` a side, each as k x k row-major sub-samples."""
    corner = torch.rand(pixels, 1, 1, 2, generator=torch.Generator().manual_seed(0)) * 0.5
    steps = (torch.arange(k, dtype=torch.float32) + 0.5) / k * side_uv
    grid = torch.stack(torch.meshgrid(steps, steps, indexing="ij"), -1)  # (k, k, 2): (down, across)
    return (corner + grid.flip(-1)[None]).reshape(-1, 2)


def test_a_photo_pixels_side_is_measured_in_texels_from_its_sub_samples():
    uv = _pixel_grid(50, 4.0 / 1024)
    assert texels_per_photo_pixel(uv, 4, 1024) == pytest.approx(4.0, rel=1e-3)
    assert texels_per_photo_pixel(uv, 4, 256) == pytest.approx(1.0, rel=1e-3)
    assert np.isnan(texels_per_photo_pixel(uv.reshape(-1, 4, 2)[:, 0], 1, 1024))  # one sub-sample: no measure


def test_the_fit_size_is_the_largest_halving_at_which_a_pixel_spans_few_texels():
    side = texels_per_photo_pixel(_pixel_grid(50, 8.0 / 1024), 4, 1024)  # 8 texels a pixel at 1024, 2 at 256, 4 at 512
    assert fit_size_for(side, 1024, 2.5) == 256
    assert fit_size_for(side, 1024, 4.5) == 512
    assert fit_size_for(side, 1024, 10.0) == 1024  # the photos as fine as the texture: fitted as it is
    assert fit_size_for(side, 1024, 0.01) == 64  # never below 64
    assert fit_size_for(side, 1024, 2.5, fixed=512) == 512
    assert fit_size_for(side, 1024, 2.5, fixed=300) == 1024  # not a halving: the texture's own size
    assert fit_size_for(side * 1000 / 1024, 1000, 2.5) == 250  # halved while it divides evenly
    assert fit_size_for(float("nan"), 1024, 2.5) == 1024  # one sub-sample a pixel: not measured, not changed


def _textures(size: int, seed: int = 0) -> BakedTextures:
    rng = np.random.default_rng(seed)
    covered = np.zeros((size, size), bool)
    covered[size // 8: size // 2, size // 8: 3 * size // 4] = True
    normal = np.zeros((size, size, 3), np.float32)
    normal[..., 2] = 1.0
    return BakedTextures(rng.uniform(0.2, 0.8, (size, size, 3)).astype(np.float32),
                         rng.uniform(0.2, 0.8, (size, size)).astype(np.float32),
                         rng.uniform(0.0, 0.3, (size, size)).astype(np.float32), normal, covered)


def test_averaging_down_keeps_each_covered_blocks_mean_and_the_coverage():
    full = _textures(64)
    coarse = averaged_down(full, 16)
    assert coarse.base_color.shape == (16, 16, 3) and coarse.covered.shape == (16, 16)
    block = (slice(4, 5), slice(4, 5))  # fully covered: fine texels 16..19
    assert coarse.base_color[block][0, 0] == pytest.approx(full.base_color[16:20, 16:20].mean(axis=(0, 1)), abs=1e-6)
    assert coarse.covered[block][0, 0] and not coarse.covered[0, 0]
    assert np.allclose(np.linalg.norm(coarse.normal, axis=-1), 1.0)


def test_a_fit_that_changed_nothing_leaves_the_baked_textures_and_a_change_is_carried_up_smoothly():
    full = _textures(64)
    coarse = averaged_down(full, 16)
    same = carried_up(full, coarse, coarse, dilation=4)
    assert np.allclose(same.base_color, full.base_color, atol=1e-6)
    assert np.allclose(same.roughness, full.roughness, atol=1e-6)
    assert same.normal is full.normal  # the normal map keeps its full size
    brighter = BakedTextures(coarse.base_color + 0.1, coarse.roughness, coarse.metallic, coarse.normal, coarse.covered)
    up = carried_up(full, coarse, brighter, dilation=16)
    inside = full.covered & (full.base_color < 0.85).all(-1)
    assert np.allclose((up.base_color - full.base_color)[inside], 0.1, atol=1e-5)  # a uniform change stays uniform


def test_an_export_far_finer_than_its_photos_is_fitted_better_at_the_photos_resolution(tmp_path, gl_context, renderer):
    """Photos of 64 px of a checker sphere, a grey sphere exported with 512 px textures (about 7 texels a
    photo pixel) and fitted to them: at the photos' resolution the export's albedo, seen by the
    renderer from the photos' cameras, is closer to the checker than fitted texel for texel at 512."""
    from dataclasses import replace

    from lirm.engine.export.export_asset import ExportConfig, export_field
    from lirm.engine.export.photo_texture_fit import TextureFitConfig
    from lirm.engine.model.analytic_fields import SphereField

    from .test_photo_texture_fit import GREY, SMALL, checker_sphere_photos, exported_albedo_error

    shoot = checker_sphere_photos(tmp_path, gl_context, renderer)
    def fitted(name: str, fit_size: int | None):
        config = ExportConfig(mesh=SMALL.mesh, texture_size=512,
                              texture_fit=replace(TextureFitConfig(), fit_size=fit_size, register_heights=0, metal_search=False,
                                                                   steps=150))
        return export_field(SphereField(0.5, pattern=GREY), tmp_path / f"{name}.glb", config, context=gl_context,
                            photos=shoot.photos, lighting=shoot.lighting)

    chosen, texel_for_texel = fitted("chosen", None), fitted("full", 512)
    report = chosen.texture_fit
    assert report.fit_size is not None and report.fit_size < 512 and report.texels_per_pixel > 4.0, report.summary()
    assert "fitted at" in report.summary()
    assert texel_for_texel.texture_fit.fit_size is None  # fitted at the export's own size
    assert chosen.textures.base_color.shape == (512, 512, 3)  # the export keeps its size
    errors = tuple(exported_albedo_error(renderer, r.path, shoot.environment, shoot.cameras, shoot.shots)
                   for r in (chosen, texel_for_texel))
    assert errors[0] < 0.5 * errors[1], errors  # (0.022 against 0.111 when written)
