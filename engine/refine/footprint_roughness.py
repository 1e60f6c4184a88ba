"""The pixel's footprint in the refinement's shading: a photo pixel is the mean over the patch of
surface it sees, and where the surface curves within that patch its reflections are blurred as a
rougher surface's would be (specular anti-aliasing, after Toksvig and Kaplanyan & Hoffman).

Why: the refinement shades one ray per pixel, at its centre. At the 128-256 px of the inputs a thin
gold rim turns its normal by more than a radian across one pixel, so its reflection in the photo is
as blurred as a roughness of 0.7-0.8 gives, and the fit, shading one normal, had to make the rim that
rough to match (measured on the held-out mug: its gold rim, truly 0.2-0.3, came back 0.78; its glaze,
truly under 0.15, 0.32). Shaded with the footprint's spread of normals added to the GGX lobe, the
fitted roughness can be the material's own, which is what the export and a relit view at any
resolution need.

The spread: the SDF's normal one footprint away along the surface in two tangent directions (across
and along the view's slant, where the footprint is longer by 1 / cos), each difference taken as a
uniform ramp over the pixel (variance of a ramp of extent d: d^2 / 12), added to the GGX lobe's
slope variance: alpha' ^ 2 = alpha ^ 2 + spread, alpha = roughness ^ 2 as the renderer has it.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

# The footprint's length along the slant grows as 1 / cos(view, normal); grazing pixels are held to
# this many footprints (their patch of surface is mostly not one surface any more).
MAX_SLANT = 4.0


@torch.no_grad()
def footprint_normal_spread(field, points: torch.Tensor, normals: torch.Tensor, directions: torch.Tensor,
                            distance: torch.Tensor, pixel_angles: torch.Tensor) -> torch.Tensor:
    """(K,) the slope variance of the SDF's normal over each pixel's patch of surface. `points`,
    `normals` (unit) and `directions` (unit, eye -> surface) are (K, 3); `distance` (K,) how far along
    the ray the surface is; `pixel_angles` (K,) the angle one pixel spans."""
    from lirm.engine.model.volume_renderer import numerical_normals

    width = distance * pixel_angles
    across = torch.linalg.cross(normals, directions, dim=-1)
    # A ray along the normal has no slant: any direction in the tangent plane will do.
    fallback = torch.linalg.cross(normals, torch.tensor([0.0, 0.0, 1.0], device=normals.device).expand_as(normals), dim=-1)
    fallback = torch.where(fallback.norm(dim=-1, keepdim=True) > 1e-3, fallback,
                           torch.linalg.cross(normals, torch.tensor([1.0, 0.0, 0.0], device=normals.device).expand_as(normals), dim=-1))
    across = F.normalize(torch.where(across.norm(dim=-1, keepdim=True) > 1e-3, across, fallback), dim=-1)
    along = torch.linalg.cross(normals, across, dim=-1)
    slant = 1.0 / (normals * directions).sum(-1).abs().clamp(min=1.0 / MAX_SLANT)
    probes = torch.cat([points + (width[:, None] * across), points + (width * slant)[:, None] * along])
    nearby = numerical_normals(field, probes).view(2, -1, 3)
    return ((nearby - normals[None]) ** 2).sum(-1).sum(0) / 12.0


def widened_roughness(roughness: torch.Tensor, spread: torch.Tensor) -> torch.Tensor:
    """The roughness whose GGX lobe is the material's widened by the footprint's `spread` of normals."""
    return (roughness.clamp(0.0, 1.0) ** 4 + spread).clamp(min=1e-8, max=1.0) ** 0.25
