"""The texture fit's shading with a hand-written backward: the split-sum mix at tabulated pixels,
averaged over each photo pixel's footprint.

`TabulatedLighting.shade` followed by the footprint's mean is what the texture fit computes at every
step, over about a million sub-samples, and autograd's version of it is some 150 element-wise
passes a step, forward and backward (each broadcast of a per-sample scalar over the colour channels
costs a reduction in the backward, the BRDF table's and the prefiltered specular's linear reads two
gathers each). Here the same values come from one function whose backward is derived by hand: the
intermediate terms are kept from the forward, every per-sample scalar's gradient is gathered into
one channel sum, and each table is read once for both rows it interpolates between. The model and
its values are `split_sum_shading.mix_split_sum`'s (tests hold values and gradients to it).

The reads it takes must lie in [0, 1] (the fit's textures are sigmoids, and bilinear reads of them
stay inside): `shade` clamps roughness and metallic there, and this leaves the clamp out.
"""

from __future__ import annotations

import torch

from .tabulated_lighting import BRDF_ROWS, TabulatedLighting, linear_row_read

# Schlick's average Fresnel over the hemisphere, f0 + (1 - f0) / 21, as mix_split_sum has it
_F_AVG_SLOPE, _F_AVG_OFFSET = 20.0 / 21.0, 1.0 / 21.0
_DIELECTRIC_F0 = 0.04


def shade_footprints(lighting: TabulatedLighting, reads: torch.Tensor, footprint: int) -> torch.Tensor:
    """(N, 3) linear radiance of each photo pixel: the mean over its `footprint` consecutive
    sub-samples of the split-sum shading (multiple scattering on) of `reads` (N * footprint, 5:
    albedo, roughness, metallic, each in [0, 1]) at the tabulated pixels. Differentiable in `reads`."""
    if reads.shape[0] != lighting.count:
        raise ValueError(f"this lighting was tabulated for {lighting.count} pixels, not {reads.shape[0]}")
    if footprint < 1 or reads.shape[0] % footprint:
        raise ValueError(f"{reads.shape[0]} sub-samples do not make whole footprints of {footprint}")
    return _FootprintShading.apply(reads, lighting, footprint)


class _FootprintShading(torch.autograd.Function):
    @staticmethod
    def forward(ctx, reads: torch.Tensor, lighting: TabulatedLighting, footprint: int) -> torch.Tensor:
        albedo, roughness, metallic = reads[:, :3], reads[:, 3:4], reads[:, 4:5]
        ab, ab_slope = linear_row_read(lighting.brdf_rows, roughness * BRDF_ROWS - 0.5)
        specular_light, specular_slope = linear_row_read(lighting.specular, roughness * (lighting.levels - 1))
        a, b = ab[:, :1], ab[:, 1:]
        irradiance, fresnel = lighting.irradiance, lighting.fresnel
        f0 = torch.addcmul(torch.full_like(albedo, _DIELECTRIC_F0), metallic, albedo - _DIELECTRIC_F0)
        gap = (1.0 - roughness) - f0  # the roughness-dependent Fresnel term is max(1 - r, f0) - f0
        above = gap > 0.0
        k_s = torch.addcmul(f0, gap.clamp(min=0.0), fresnel)
        fss_ess = torch.addcmul(b, k_s, a)
        ems = 1.0 - a - b
        f_avg = f0 * _F_AVG_SLOPE + _F_AVG_OFFSET
        denominator = 1.0 - f_avg * ems
        q = ems * f_avg / denominator  # fms_ems = fss_ess * q
        fms_ems = fss_ess * q
        diffuse_colour = albedo * (1.0 - metallic)
        remainder = 1.0 - fss_ess - fms_ems  # what the diffuse lobe keeps
        radiance = fss_ess * specular_light + (fms_ems + diffuse_colour * remainder) * irradiance
        ctx.save_for_backward(albedo, metallic, specular_light, specular_slope, ab_slope, a, k_s, fss_ess, ems, f_avg,
                              denominator, q, diffuse_colour, remainder, above, irradiance, fresnel)
        ctx.footprint = footprint
        ctx.levels_span = float(lighting.levels - 1)  # d(specular position) / d(roughness)
        return radiance.reshape(-1, footprint, 3).mean(1)

    @staticmethod
    def backward(ctx, gradient: torch.Tensor):
        (albedo, metallic, specular_light, specular_slope, ab_slope, a, k_s, fss_ess, ems, f_avg, denominator, q,
         diffuse_colour, remainder, above, irradiance, fresnel) = ctx.saved_tensors
        g = (gradient / ctx.footprint).repeat_interleave(ctx.footprint, dim=0)  # each sub-sample's share of the mean
        lit = g * irradiance
        # radiance = fss_ess * specular_light + (fms_ems + diffuse_colour * remainder) * irradiance,
        # fms_ems = fss_ess * q, remainder = 1 - fss_ess - fms_ems
        d_fms = lit - lit * diffuse_colour
        d_fss = torch.addcmul(g * specular_light - lit * diffuse_colour, d_fms, q)
        d_diffuse_colour = lit * remainder
        # q = ems * f_avg / (1 - f_avg * ems): its derivatives are ems / den^2 and f_avg / den^2
        d_q_over_den2 = d_fms * fss_ess / (denominator * denominator)
        d_ems = d_q_over_den2 * f_avg  # per channel: ems is one per sample, summed with the rest below
        d_k_s = d_fss * a
        d_gap = d_k_s * fresnel * above
        d_f0 = d_q_over_den2 * ems * _F_AVG_SLOPE + d_k_s - d_gap
        # roughness, one channel sum: through 1 - r (the gap), the BRDF table's (A, B) (ems = 1 - A - B,
        # fss_ess = k_s A + B) and the prefiltered specular
        d_a = d_fss * k_s - d_ems
        d_b = d_fss - d_ems
        through_tables = (d_a * ab_slope[:, :1] + d_b * ab_slope[:, 1:]) * BRDF_ROWS
        through_tables = torch.addcmul(through_tables, g * fss_ess, specular_slope, value=ctx.levels_span)
        d_roughness = (through_tables - d_gap).sum(-1, keepdim=True)
        # f0 = 0.04 + m (albedo - 0.04), diffuse_colour = albedo (1 - m)
        d_albedo = torch.addcmul(d_f0 * metallic, d_diffuse_colour, 1.0 - metallic)
        d_metallic = (d_f0 * (albedo - _DIELECTRIC_F0) - d_diffuse_colour * albedo).sum(-1, keepdim=True)
        return torch.cat([d_albedo, d_roughness, d_metallic], -1), None, None
