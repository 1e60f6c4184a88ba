"""An albedo that does not follow the surface's facing (losses.albedo_unshaded; README: what it was
worth).

Why: the photos of a capture ring see the surroundings at the cameras' height and below, never the
lights above them, so the fitted lighting starts dark where most of the light comes from. The fit
can then explain a surface that is brighter where it faces up either by a brighter sky or by a
brighter albedo there, and the albedo, being per point, takes it first: the shading the inputs were
lit with stays in the albedo (a vase darker toward its foot, a mug's rim tinted by the sky), and
the asset relights wrong. Diffuse shading under any distant light is, to a good approximation, a
smooth function of the normal whose largest part beyond the mean is linear in it (the first band of
spherical harmonics). Paint has no reason to be: so the term fits, over a batch's surface points,
the log albedo as a linear function of the normal, and penalises the part the normal explains. What
it takes from the albedo only the lighting can then give back.

It is a prior, not a law: a paint that really is darker where it faces down (a dark foot) is pulled
too, so it is weighted weakly, and a batch's points are spread over every view, so that the fit
sees the whole object.
"""

from __future__ import annotations

import torch


MIN_POINTS = 32  # fewer surface points say nothing reliable about how the albedo follows the normal
RIDGE = 1e-3  # relative regularisation of the fit (a batch whose normals all point one way)


def normal_explained_albedo(albedo: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """(N, 3) linear albedo, (N, 3) normals at surface points -> the mean squared part of the log
    albedo (per channel) that a linear function of the normal explains, over the points. The normal
    is taken as given (no gradient): the term moves the albedo, not the surface."""
    if albedo.shape[0] < MIN_POINTS:
        return albedo.new_zeros(())
    log_albedo = albedo.clamp(min=1e-3).log()
    n = torch.nn.functional.normalize(normal.detach(), dim=-1)
    n = n - n.mean(dim=0, keepdim=True)
    y = log_albedo - log_albedo.mean(dim=0, keepdim=True)
    gram = n.T @ n
    ridge = RIDGE * gram.diagonal().sum().clamp(min=1e-6) * torch.eye(3, device=n.device, dtype=n.dtype)
    coefficients = torch.linalg.solve(gram + ridge, n.T @ y)  # (3, 3): normal -> log albedo, per channel
    explained = n @ coefficients
    return (explained**2).sum(-1).mean()
