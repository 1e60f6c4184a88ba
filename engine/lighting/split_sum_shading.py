"""The renderer's image-based shading (renderer/shaders/mesh_pbr.frag) in torch, so that it differentiates.

Same model, line for line: glTF metallic-roughness, GGX with height-correlated Smith visibility, the
split-sum approximation with the renderer's own prefiltered specular levels, irradiance and BRDF
table (read back from the GPU by lighting_tables.py), Fdez-Aguera's roughness-dependent Fresnel and
multiple-scattering compensation. The prefiltered maps are held as equirectangular tables instead of
cube maps (torch has no cube sampler); a test holds the two renderers within 1% on a sphere.

Everything is differentiable with respect to the G-buffer (albedo, roughness, metallic, normal) and
to the tables themselves, so a lighting estimate can be fitted through it too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch


@dataclass
class SplitSumTables:
    """Prefiltered lighting for one environment, in the environment's own frame (+Z up)."""

    specular: list[torch.Tensor]  # level k: (H_k, W_k, 3) radiance prefiltered for roughness k / (levels - 1)
    irradiance: torch.Tensor  # (H, W, 3) irradiance / pi, in radiance units
    brdf_lut: torch.Tensor  # (S, S, 2): (A, B), rows = roughness, columns = N.V, texel centres at (i + 0.5) / S
    world_to_environment: torch.Tensor  # (3, 3): the renderer's rotation about +Z
    intensity: float = 1.0  # 2^intensity_ev

    @property
    def levels(self) -> int:
        return len(self.specular)

    def to(self, device: torch.device | str, dtype: torch.dtype = torch.float32) -> "SplitSumTables":
        return SplitSumTables([s.to(device, dtype) for s in self.specular], self.irradiance.to(device, dtype),
                              self.brdf_lut.to(device, dtype), self.world_to_environment.to(device, dtype), self.intensity)

    # The lighting interface `shade` reads (panorama_lighting.py gives the same from a learnable panorama).
    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return prefiltered_specular(self, directions @ self.world_to_environment.T, roughness) * self.intensity

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        return equirect_lookup(self.irradiance, normals @ self.world_to_environment.T) * self.intensity

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return lut_lookup(self.brdf_lut, n_dot_v, roughness)


def equirect_lookup(table: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
    """Bilinear (H, W, C) lookup at unit directions (N, 3), wrapping in longitude: the same mapping
    as renderer/environment.py (image centre along +X, row 0 the zenith)."""
    h, w = table.shape[0], table.shape[1]
    d = directions / directions.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    u = torch.remainder(0.5 - torch.atan2(d[:, 1], d[:, 0]) / (2.0 * math.pi), 1.0)
    v = torch.acos(d[:, 2].clamp(-1.0 + 1e-7, 1.0 - 1e-7)) / math.pi
    x = u * w - 0.5
    y = (v * h - 0.5).clamp(0.0, h - 1.0)
    x0, y0 = torch.floor(x), torch.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0i = torch.remainder(x0.long(), w)
    x1i = torch.remainder(x0i + 1, w)
    y0i = y0.long().clamp(0, h - 1)
    y1i = (y0i + 1).clamp(max=h - 1)
    flat = table.reshape(h * w, -1)
    top = flat[y0i * w + x0i] * (1 - fx) + flat[y0i * w + x1i] * fx
    bottom = flat[y1i * w + x0i] * (1 - fx) + flat[y1i * w + x1i] * fx
    return top * (1 - fy) + bottom * fy


def lut_lookup(lut: torch.Tensor, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
    """GL_LINEAR with clamp-to-edge on the (S, S, 2) BRDF table at (x = N.V, y = roughness)."""
    s = lut.shape[0]
    x = (n_dot_v * s - 0.5).clamp(0.0, s - 1.0)
    y = (roughness * s - 0.5).clamp(0.0, s - 1.0)
    x0, y0 = torch.floor(x), torch.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0i, y0i = x0.long(), y0.long()
    x1i, y1i = (x0i + 1).clamp(max=s - 1), (y0i + 1).clamp(max=s - 1)
    flat = lut.reshape(s * s, 2)
    top = flat[y0i * s + x0i] * (1 - fx) + flat[y0i * s + x1i] * fx
    bottom = flat[y1i * s + x0i] * (1 - fx) + flat[y1i * s + x1i] * fx
    return top * (1 - fy) + bottom * fy


def prefiltered_specular(tables: SplitSumTables, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
    """Trilinear across the prefiltered levels, as textureLod(cube, r, roughness * (levels - 1))."""
    lod = roughness.clamp(0.0, 1.0) * (tables.levels - 1)
    out = torch.zeros(directions.shape[0], 3, dtype=directions.dtype, device=directions.device)
    for level, table in enumerate(tables.specular):
        weight = (1.0 - (lod - level).abs()).clamp(min=0.0)  # hat function: the two nearest levels
        used = weight > 0
        if used.any():
            out = out.index_add(0, used.nonzero()[:, 0], weight[used, None] * equirect_lookup(table, directions[used]))
    return out


@dataclass
class ShadingTerms:
    radiance: torch.Tensor  # (N, 3) linear HDR, as the renderer's radiance attachment
    diffuse: torch.Tensor  # (N, 3) the part of it the diffuse layer gives
    specular: torch.Tensor  # (N, 3) the specular part (single + multiple scattering)


def shade(lighting, albedo: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor,
          normal: torch.Tensor, view: torch.Tensor, multiple_scattering: bool = True) -> ShadingTerms:
    """Outgoing radiance toward `view` (unit, surface -> eye) of (N,) surface points. Mirrors mesh_pbr.frag.

    `lighting` gives prefiltered(world directions, roughness), irradiance_over_pi(world normals) and
    brdf(N.V, roughness) -> (A, B): SplitSumTables (the renderer's own maps) or a PanoramaLighting."""
    roughness = roughness.clamp(0.0, 1.0)
    metallic = metallic.clamp(0.0, 1.0)
    n = normal / normal.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    v = view / view.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    cos = (n * v).sum(-1)
    n_dot_v = cos.clamp(1e-4, 1.0)
    ab = lighting.brdf(n_dot_v, roughness)
    reflected = 2.0 * cos[:, None] * n - v  # GLSL reflect(-v, n)
    specular_light = lighting.prefiltered(reflected, roughness)
    irradiance = lighting.irradiance_over_pi(n)
    return mix_split_sum(albedo, roughness, metallic, fresnel_weight(n_dot_v), ab, specular_light, irradiance,
                         multiple_scattering)


def fresnel_weight(n_dot_v: torch.Tensor) -> torch.Tensor:
    """(N, 1) Schlick's (1 - N.V)^5: fixed wherever the geometry is (tabulated_lighting.py keeps it)."""
    return (1.0 - n_dot_v)[:, None] ** 5


def mix_split_sum(albedo: torch.Tensor, roughness: torch.Tensor, metallic: torch.Tensor, fresnel: torch.Tensor,
                  ab: torch.Tensor, specular_light: torch.Tensor, irradiance: torch.Tensor,
                  multiple_scattering: bool = True) -> ShadingTerms:
    """The material half of `shade`: the lighting's terms at each point (the BRDF table's (A, B), the
    prefiltered specular along the reflection, the irradiance / pi, and `fresnel_weight` of its N.V)
    mixed by the albedo, roughness (clamped) and metallic (clamped), as mesh_pbr.frag mixes them."""
    m = metallic[:, None]
    diffuse_colour = albedo * (1.0 - m)
    f0 = 0.04 * (1.0 - m) + albedo * m
    a, b = ab[:, :1], ab[:, 1:]
    fresnel_roughness = torch.maximum((1.0 - roughness)[:, None].expand_as(f0), f0) - f0
    k_s = f0 + fresnel_roughness * fresnel
    fss_ess = k_s * a + b
    if multiple_scattering:
        ems = 1.0 - (a + b)
        f_avg = f0 + (1.0 - f0) / 21.0
        fms_ems = ems * fss_ess * f_avg / (1.0 - f_avg * ems)
    else:
        fms_ems = torch.zeros_like(fss_ess)
    k_d = diffuse_colour * (1.0 - fss_ess - fms_ems)
    specular = fss_ess * specular_light + fms_ems * irradiance
    diffuse = k_d * irradiance
    return ShadingTerms(specular + diffuse, diffuse, specular)
