"""Surfaces painted alike share their roughness and metallic (losses.shared_materials; README: what
it was worth).

Why: at 128 px a glaze's highlight or a metal band's reflection covers a few pixels of a few views,
and only those pixels say what the material is; everywhere else the photos are nearly as well
explained by a rough, dull surface with the shading in the albedo. Holding each surface point's
roughness and metallic to those of the batch's points with a like albedo (a Gaussian kernel on the
albedo: a non-local, bilateral smoothing over the whole object, not only a pixel's neighbours)
carries what the few pixels say to the whole paint, as a per-material BRDF would, while points of
another paint (a gold line on a cream glaze) stay free. A batch's surface points are spread over
every view, so the batch stands in for the object; no state is kept between steps.
"""

from __future__ import annotations

import torch


ALBEDO_SIGMA = 0.05  # albedo difference (display-like units, `albedo_features`) still counted as one paint


def albedo_features(albedo: torch.Tensor) -> torch.Tensor:
    """Linear albedo -> a display-like space, where distances between paints are closer to what an eye
    (and the photo's 8 bits) tells apart than in linear light."""
    return albedo.clamp(0.0, 1.0) ** (1.0 / 2.2)


def like_albedo_targets(albedo: torch.Tensor, values: torch.Tensor, sigma: float = ALBEDO_SIGMA) -> torch.Tensor:
    """(N, 3) albedo, (N, C) values -> (N, C): each point's kernel-weighted mean of the values over the
    points with a like albedo (itself included), without gradient."""
    with torch.no_grad():
        features = albedo_features(albedo.detach())
        kernel = torch.exp(-torch.cdist(features, features) ** 2 / (2.0 * sigma**2))
        return (kernel @ values.detach()) / kernel.sum(dim=1, keepdim=True)


def shared_material_loss(albedo: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor | None,
                         sigma: float = ALBEDO_SIGMA) -> torch.Tensor:
    """(N, 3), (N,), (N,) at surface points -> the mean squared distance of each point's roughness and
    metallic to those of its paint (like_albedo_targets); without `metallic`, of the roughness only."""
    materials = torch.stack([roughness] + ([] if metallic is None else [metallic]), dim=-1)
    return _spread_within_paints(albedo, materials, sigma)


def _spread_within_paints(albedo: torch.Tensor, values: torch.Tensor, sigma: float) -> torch.Tensor:
    """(N, 3) albedo, (N, C) values -> the mean squared distance of each point's values to its paint's
    (like_albedo_targets); 0 for fewer than two points."""
    if albedo.shape[0] < 2:
        return values.new_zeros(())
    return ((values - like_albedo_targets(albedo, values, sigma)) ** 2).sum(-1).mean()


def shared_albedo_loss(albedo: torch.Tensor, sigma: float = ALBEDO_SIGMA) -> torch.Tensor:
    """(N, 3) albedo at surface points -> the mean squared distance of each to the mean albedo of its
    paint (like_albedo_targets of the albedo itself: one mean-shift step). Within a paint the albedo
    is pulled flat, so a slow change of brightness over it (shading that a wrong light left there)
    must be explained by the light and the surface instead; another paint, a kernel width away or
    more, is not pulled."""
    return _spread_within_paints(albedo, albedo, sigma)
