import torch

from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.engine.refine.roughness_observability import roughness_sensitivity, unseen_roughness_term


def _sensitivity(lighting, albedo, roughness, metallic, normals):
    n = normals.shape[0]
    albedo, roughness, metallic = albedo.expand(n, 3), torch.full((n,), roughness), torch.full((n,), metallic)
    view = normals  # each point seen head-on: its mirror direction is its normal
    with torch.no_grad():
        display = radiance_to_display_torch(shade(lighting, albedo, roughness, metallic, normals, view).radiance,
                                            lighting.camera_response)
    return roughness_sensitivity(lighting, albedo, roughness, metallic, normals, view, display)


def _normals() -> torch.Tensor:
    return torch.nn.functional.normalize(torch.randn(2000, 3, generator=torch.Generator().manual_seed(0)), dim=-1)


def _sunny() -> PanoramaLighting:
    """A light 4 x the sky around it (a brighter one saturates the tone curve, where no roughness shows)."""
    sun = torch.zeros(16, 32, 3)
    sun[4, 10] = torch.log(torch.tensor(4.0))
    return PanoramaLighting(sun)


def test_a_highlight_says_far_more_about_the_roughness_than_a_matte_side_under_a_flat_sky():
    normals = _normals()
    flat = PanoramaLighting(torch.zeros(16, 32, 3))
    # The metal's roughness, 0.45: above the panorama's sharpest lobe (a texel), below which the shading does
    # not change.
    matte = _sensitivity(flat, torch.tensor([0.5, 0.5, 0.5]), 0.6, 0.0, normals)
    mirror = _sensitivity(_sunny(), torch.tensor([0.5, 0.5, 0.5]), 0.45, 1.0, normals)
    assert matte.shape == (2000,) and torch.isfinite(matte).all() and (matte >= 0).all()
    assert float(matte.max()) < 0.1  # a flat sky's reflection is the same at any roughness
    assert float(mirror.max()) > 10 * float(matte.max())  # facing the sun, the lobe's width is the whole picture


def test_the_hold_is_plain_l1_where_the_photo_is_silent_and_fades_where_it_speaks():
    roughness, target = torch.tensor([0.2, 0.8]), torch.tensor([0.6, 0.4])
    silent = unseen_roughness_term(roughness, target, torch.zeros(2), scale=0.2)
    assert torch.isclose(silent, (roughness - target).abs().mean())
    speaking = unseen_roughness_term(roughness, target, torch.full((2,), 0.2), scale=0.2)
    assert torch.isclose(speaking, 0.5 * silent)  # halved at the scale
    assert float(unseen_roughness_term(roughness, target, torch.full((2,), 1e4), scale=0.2)) < 1e-4


def test_below_the_panoramas_sharpest_lobe_the_photo_says_nothing_about_the_roughness():
    # At 16 x 32 texels the narrowest lobe the fitted panorama shades is a texel's (a roughness of about
    # 0.25): a glaze of 0.1 shades as one of 0.15, so only a prior can tell them apart (README).
    normals, sunny = _normals(), _sunny()
    glossy = _sensitivity(sunny, torch.tensor([0.5, 0.5, 0.5]), 0.1, 1.0, normals)
    wider = _sensitivity(sunny, torch.tensor([0.5, 0.5, 0.5]), 0.3, 1.0, normals)
    assert float(glossy.max()) < 0.01 < 0.5 < float(wider.max())
