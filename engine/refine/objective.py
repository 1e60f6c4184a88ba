"""The refinement's loss on one batch of rays: photometric, mask, eikonal, normal, albedo and a weak
material prior (weights in config.LossWeights; the README says what each was worth)."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import torch
import torch.nn.functional as F

from lirm.engine.lighting.camera_response import display_to_radiance_torch, radiance_to_display_torch
from lirm.engine.lighting.split_sum_shading import shade

from .albedo_smoothness import albedo_difference
from .config import CURVATURE_STEP, LossWeights
from .footprint_roughness import widened_roughness
from .image_materials import image_material_terms
from .outside_bounds import OutsideBounds
from .roughness_observability import roughness_sensitivity, unseen_roughness_term
from .ray_rendering import RayBatchRender
from .shared_materials import ALBEDO_SIGMA, shared_albedo_loss, shared_material_loss
from .unshaded_albedo import normal_explained_albedo


VOLUME_BAND = 0.02  # of the bounding radius: the soft step of the volume term (its push acts within this of the surface)


def srgb_to_linear_torch(c: torch.Tensor) -> torch.Tensor:
    c = c.clamp(0.0, 1.0)
    return torch.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def sdf_gradients(field, points: torch.Tensor, eps: float) -> torch.Tensor:
    """(K, 3) -> (K, 3) central differences of the SDF (differentiable: the eikonal term trains on them)."""
    return sdf_values_and_gradients(field, points, eps)[1]


def sdf_values_and_gradients(field, points: torch.Tensor, eps: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(K, 3) -> the SDF at the points ((K,): the mean of the six probes, exact to eps²) and its central
    differences ((K, 3)), from one read of the planes."""
    offsets = torch.eye(3, device=points.device, dtype=points.dtype) * eps
    probes = torch.cat([points[:, None] + offsets[None], points[:, None] - offsets[None]], dim=1)
    s = field.sdf(probes.reshape(1, -1, 3))[0].view(-1, 6)
    return s.mean(dim=1), (s[:, :3] - s[:, 3:]) / (2.0 * eps)


def batch_loss(field, render: RayBatchRender, colours: torch.Tensor, alphas: torch.Tensor, weights: LossWeights,
               eikonal_points: int, generator: torch.Generator, lighting=None,
               directions: torch.Tensor | None = None,
               material_anchor: Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]] | None = None,
               volume_points: torch.Tensor | None = None, floor=None,
               floor_points: torch.Tensor | None = None,
               pairs: torch.Tensor | None = None,
               outside_points: torch.Tensor | None = None,
               material_targets: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, float]]:
    """With `lighting` (a PanoramaLighting) and the rays' `directions`, the inverse-rendering terms too.
    `material_anchor` (points -> roughness, metallic): what the material prior holds the field to at
    the surface points, e.g. the LIRM prediction the fit started from; without it the prior is the
    constant roughness 0.5 and metallic 0 over each ray. `volume_points`: (K, 3) points spread over
    where the object may be, for the volume term. `floor` (unseen_floor.UnseenFloor) and its
    `floor_points` below it: the floor term. `pairs`: (P, 2) batch positions of nearby rays of one
    view, for the albedo smoothness term (with the inverse rendering). `outside_points`: (K, 4) points
    outside the sampling grid with the SDF's lower bound at each (outside_bounds.py), for the term
    that keeps the field empty where the fit never renders. `material_targets`: (N, 5) the material
    network's metallic, roughness and albedo at each ray's pixel (image_materials.py)."""
    terms: dict[str, torch.Tensor] = {}
    terms["colour"] = (render.colour - colours).abs().mean()
    if lighting is not None:
        terms.update(inverse_rendering_terms(render, colours, alphas, lighting, directions, delit=weights.albedo_delit > 0,
                                             shared_materials=weights.shared_materials > 0,
                                             share_metallic=weights.share_metallic, sigma=weights.shared_albedo_sigma,
                                             unshaded_albedo=weights.albedo_unshaded > 0,
                                             shared_albedo=weights.shared_albedo > 0,
                                             light_neutral=weights.light_neutral > 0,
                                             material_targets=material_targets if weights.reads_material_network else None,
                                             image_albedo=weights.image_albedo > 0, image_albedo_shade=weights.image_albedo_shade > 0,
                                             unseen_roughness=weights.image_roughness_unseen > 0,
                                             unseen_roughness_scale=weights.unseen_roughness_scale))
        if weights.albedo_pairs and pairs is not None and pairs.shape[0]:
            terms["albedo_pairs"] = paired_albedo_smoothness(render, colours, alphas, pairs, lighting.camera_response)
        weights = replace(weights, albedo=0.0)  # the albedo is fitted through the shading, not to the colour
    if weights.mask:
        opacity = render.opacity.clamp(1e-4, 1.0 - 1e-4)
        terms["mask"] = F.binary_cross_entropy(opacity, alphas)
    if weights.albedo:
        # Until the materials are inverse-rendered, the albedo follows the observed colour, linearised
        # (as the carved hull colours its voxels): premultiplied like the render's albedo.
        target = srgb_to_linear_torch(colours) * render.opacity.detach()[:, None]
        terms["albedo"] = (render.albedo - target).abs().mean()
    if weights.material_prior and material_anchor is None:
        o = render.opacity.detach()
        terms["material_prior"] = ((render.roughness - 0.5 * o) ** 2 + render.metallic**2).mean()
    # Terms on sampled surface points need some: with none (eikonal_points 0) their means would be NaN.
    if ((weights.eikonal or weights.normal or weights.curvature or weights.albedo_smooth)
            and render.surface_points.shape[0] and eikonal_points > 0):
        points = render.surface_points
        if points.shape[0] > eikonal_points:
            points = points[torch.randint(0, points.shape[0], (eikonal_points,), generator=generator)]
        # Half as many points anywhere in the bounding sphere keep the SDF a distance away from the surface too.
        far = (torch.rand(eikonal_points // 2, 3, generator=generator) * 2.0 - 1.0) * field.radius
        probes = torch.cat([points, far.to(points)])
        count = probes.shape[0]
        if weights.curvature:
            # The surface's normal should change little over a short step: lumps a few views cannot
            # see (they cost the relighting, where every bump catches the new light) are flattened.
            # Its probes are read with the eikonal's in one pass over the planes.
            step = torch.randn(points.shape[0], 3, generator=generator).to(points) * weights.curvature_step * field.radius
            probes = torch.cat([probes, points + step])
        outside = weights.outside_bounds and outside_points is not None
        if outside:
            # Read with the eikonal's probes in one pass: a read of its own cost a fifth of a step
            # (each read's backward fills a gradient the size of the planes).
            before_outside = probes.shape[0]
            probes = torch.cat([probes, outside_points[:, :3]])
        values, gradients = sdf_values_and_gradients(field, probes, 0.5 * field.normal_eps)
        if outside:
            terms["outside_bounds"] = OutsideBounds.shortfall(outside_points[:, 3], values[before_outside:])
        gradient = gradients[:count]
        terms["eikonal"] = ((gradient.norm(dim=-1) - 1.0) ** 2).mean()
        if weights.curvature:
            here, nearby = gradient[: points.shape[0]], gradients[count:count + points.shape[0]]
            terms["curvature"] = (1.0 - F.cosine_similarity(here, nearby, dim=-1)).mean()
        if weights.albedo_smooth:
            offsets = torch.randn(points.shape[0], 3, generator=generator).to(points) * CURVATURE_STEP * field.radius
            terms["albedo_smooth"] = albedo_difference(field, points, offsets)
        if weights.normal or (weights.material_prior and material_anchor is not None):
            at_surface = field.sample(points[None])
        if weights.normal:
            numerical = F.normalize(gradient[: points.shape[0]], dim=-1).detach()
            terms["normal"] = (1.0 - (at_surface.normal[0] * numerical).sum(-1)).mean()
        if weights.material_prior and material_anchor is not None:
            # Where the photos say nothing about the materials (a plain fit of the radiance), the
            # prior's prediction is the best guess there is: keep it instead of a constant.
            roughness, metallic = material_anchor(points)
            terms["material_prior"] = ((at_surface.roughness[0] - roughness) ** 2 + (at_surface.metallic[0] - metallic) ** 2).mean()
    if weights.volume and volume_points is not None and volume_points.shape[0]:
        band = VOLUME_BAND * field.radius
        terms["volume"] = torch.sigmoid(-field.sdf(volume_points[None])[0] / band).mean()
    if weights.floor and floor is not None and floor_points is not None:
        terms["floor"] = floor.loss(field, floor_points)
    if weights.outside_bounds and outside_points is not None and "outside_bounds" not in terms:
        terms["outside_bounds"] = OutsideBounds.loss(field, outside_points)
    if weights.plane_tv:
        planes = field.planes
        terms["plane_tv"] = ((planes[..., 1:, :] - planes[..., :-1, :]) ** 2).mean() + ((planes[..., 1:] - planes[..., :-1]) ** 2).mean()
    total = sum(getattr(weights, name) * value for name, value in terms.items())
    return total, {name: float(value.detach()) for name, value in terms.items()}


def inverse_rendering_terms(render: RayBatchRender, colours: torch.Tensor, alphas: torch.Tensor, lighting,
                            directions: torch.Tensor, delit: bool = False,
                            shared_materials: bool = False, share_metallic: bool = True,
                            sigma: float = ALBEDO_SIGMA, unshaded_albedo: bool = False, shared_albedo: bool = False,
                            light_neutral: bool = False, material_targets: torch.Tensor | None = None,
                            image_albedo: bool = False, image_albedo_shade: bool = False,
                            unseen_roughness: bool = False,
                            unseen_roughness_scale: float = LossWeights.unseen_roughness_scale) -> dict[str, torch.Tensor]:
    """The PBR materials at the rays' surfaces shaded under `lighting` (the renderer's split-sum model),
    through the camera's tone curve, against the photo, where both say object; and the lighting's own
    terms (what the backgrounds saw, smoothness)."""
    opacity = render.opacity
    solid = (alphas > 0.99) & (opacity.detach() > 0.5)
    terms = {"light_seen": lighting.observation_loss(), "light_smooth": lighting.smoothness_loss()}
    if light_neutral:
        terms["light_neutral"] = lighting.neutrality_loss()
    if not solid.any():
        terms["pbr"] = opacity.new_zeros(())
        return terms
    o = opacity[solid].clamp(min=1e-3)
    albedo = (render.albedo[solid] / o[:, None]).clamp(0.0, 1.0)
    roughness = (render.roughness[solid] / o).clamp(0.0, 1.0)
    metallic = (render.metallic[solid] / o).clamp(0.0, 1.0)
    normal, view = render.normal[solid], -directions[solid]
    # The lobe the pixel sees: the material's, widened by the curve of the surface across the pixel.
    seen_roughness = roughness if render.normal_spread is None else widened_roughness(roughness, render.normal_spread[solid])
    shaded = shade(lighting, albedo, seen_roughness, metallic, normal, view).radiance
    shaded_display = radiance_to_display_torch(shaded, lighting.camera_response)
    terms["pbr"] = (shaded_display - colours[solid]).abs().mean()
    if material_targets is not None:
        targets = material_targets[solid]
        terms.update(image_material_terms(roughness, metallic, albedo, targets, image_albedo, image_albedo_shade))
        if unseen_roughness:
            sensitivity = roughness_sensitivity(lighting, albedo.detach(), seen_roughness.detach(), metallic.detach(),
                                                normal.detach(), view, shaded_display.detach())
            terms["image_roughness_unseen"] = unseen_roughness_term(roughness, targets[:, 1], sensitivity, unseen_roughness_scale)
    if shared_materials:
        terms["shared_materials"] = shared_material_loss(albedo, roughness, metallic if share_metallic else None, sigma)
    if shared_albedo:
        terms["shared_albedo"] = shared_albedo_loss(albedo, sigma)
    if unshaded_albedo:
        terms["albedo_unshaded"] = normal_explained_albedo(albedo, normal)
    if not delit:  # its four extra shadings per ray are only worth paying for when the term counts
        return terms
    target, usable = delit_albedo(lighting, colours[solid], seen_roughness.detach(), metallic.detach(), normal.detach(), view)
    if usable.any():
        terms["albedo_delit"] = (albedo[usable] - target[usable]).abs().mean()
    return terms


PAIR_CHROMA_SIGMA = 0.03  # chromaticity difference (r, g, b over their sum) that still counts as the same colour
PAIR_MIN_RADIANCE = 0.02  # darker pixels' chromaticity is mostly noise: they are left out


def paired_albedo_smoothness(render: RayBatchRender, colours: torch.Tensor, alphas: torch.Tensor,
                             pairs: torch.Tensor, camera_response: str = "aces") -> torch.Tensor:
    """Nearby rays whose photo colours have the same chromaticity, weighted by how alike it is, should
    have the same albedo: shading scales the linear colour and leaves its chromaticity, a change of
    paint changes both. Without it the albedo may absorb whatever shading the lighting gets wrong
    (an unseen light's side, a lumpy normal) and the lighting is never made to explain it; with it
    a painted band round the object carries the light's fall-off to the lighting."""
    i, j = pairs[:, 0], pairs[:, 1]
    opacity = render.opacity
    solid = (alphas[i] > 0.99) & (alphas[j] > 0.99) & (opacity[i].detach() > 0.5) & (opacity[j].detach() > 0.5)
    with torch.no_grad():
        linear = display_to_radiance_torch(colours.clamp(0.0, 0.98), camera_response)
        total = linear.sum(-1, keepdim=True)
        chroma = linear / total.clamp(min=1e-6)
        alike = torch.exp(-((chroma[i] - chroma[j]) ** 2).sum(-1) / (2.0 * PAIR_CHROMA_SIGMA**2))
        bright = (total[i, 0] > PAIR_MIN_RADIANCE) & (total[j, 0] > PAIR_MIN_RADIANCE)
        weight = alike * (solid & bright).to(alike.dtype)
    if not bool(weight.any()):
        return opacity.new_zeros(())
    albedo = render.albedo / opacity.clamp(min=1e-3)[:, None]
    difference = (albedo[i] - albedo[j]).abs().sum(-1)
    return (weight * difference).sum() / weight.sum().clamp(min=1.0)


@torch.no_grad()
def delit_albedo(lighting, colours: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor, normal: torch.Tensor,
                 view: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The albedo that would shade to each photo colour under the current lighting, normal, roughness
    and metallic: the shading is (nearly) affine in the albedo, so shading with albedo 0 and 1 and
    solving per channel de-lights the photo in closed form. A direct, per-ray target for the albedo
    (the photometric term alone reaches it only through the tone curve, slowly); pixels near
    clipping (a lower bound only) and ones the light barely reaches are left out."""
    radiance = display_to_radiance_torch(colours, lighting.camera_response)
    shaded = lambda albedo: shade(lighting, albedo, roughness, metallic, normal, view).radiance  # noqa: E731
    dark, lit = shaded(torch.zeros_like(colours)), shaded(torch.ones_like(colours))
    gain = lit - dark
    target = ((radiance - dark) / gain.clamp(min=1e-6)).clamp(0.0, 1.0)
    # Metal makes the Fresnel (and the multiple-scattering term) depend on the albedo too: one Newton
    # step from the affine solution takes what remains.
    step = 1e-2
    at = shaded(target)
    slope = ((shaded(target + step) - at) / step).clamp(min=1e-6)
    target = (target - (at - radiance) / slope).clamp(0.0, 1.0)
    usable = (colours.max(dim=-1).values < 0.98) & (gain.min(dim=-1).values > 1e-3 * gain.max().clamp(min=1e-6))
    return target, usable
