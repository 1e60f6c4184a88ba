"""A low-resolution environment that the refinement can fit, with the split-sum lighting terms
computed from it directly in torch (so they differentiate with respect to every texel).

Parametrised as log-radiance on a small equirectangular grid (16 x 32 by default: 11 degree texels,
enough for the diffuse light and the broad lobes that carry most of what a few photos say about
light). The split-sum pieces:
- irradiance / pi at a normal: the cosine-weighted sum over texels (exact for this panorama);
- prefiltered specular at a reflected direction and roughness: the texels weighted by a spherical
  Gaussian lobe around it (the usual fit of GGX, sharpness 2 / alpha^2 about the half vector, so
  1 / (2 alpha^2) about the reflected direction), its width never below the texel spacing;
- the BRDF table (A, B): integrated once in numpy (renderer/brdf_reference.py) and cached.

Optionally, compact lights (`light_lobes`): spherical Gaussian lobes with a free axis, colour and
width, added to the panorama's texels. The smoothness term (total variation of the log radiance)
prices a small bright source far above a broad dim glow of the same energy, so without them a sun
or a lamp no photo saw comes out as a low, wide glow; a lobe carries one at no smoothness cost.
"""

from __future__ import annotations

import functools
import math

import numpy as np
import torch

from lirm.renderer.brdf_reference import split_sum_terms
from lirm.renderer.environment import Environment

from .split_sum_shading import lut_lookup


@functools.lru_cache(maxsize=2)
def brdf_table(size: int = 32, samples: int = 4096) -> torch.Tensor:
    """(size, size, 2): rows = roughness, columns = N.V at texel centres, as the renderer's LUT."""
    table = np.zeros((size, size, 2), np.float32)
    for row in range(size):
        for col in range(size):
            table[row, col] = split_sum_terms((col + 0.5) / size, (row + 0.5) / size, samples=samples, seed=row * size + col)
    return torch.from_numpy(table)


class PanoramaLighting(torch.nn.Module):
    def __init__(self, log_radiance: torch.Tensor, sharpest_lobe_texels: float = 1.0, light_lobes: int = 0,
                 smoothness_scale: float = 0.0, camera_response: str = "aces"):
        super().__init__()
        # 0: the smoothness term is the plain total variation of the log radiance; above 0, a step of
        # log contrast d costs scale * log(1 + d / scale) (`smoothness_loss`).
        self.smoothness_scale = float(smoothness_scale)
        # The camera's tone curve that the photos shaded under this light are compared through
        # (camera_response.RESPONSES): the one the capture's estimate was read with.
        self.camera_response = camera_response
        height, width = log_radiance.shape[:2]
        self.log_radiance = torch.nn.Parameter(log_radiance.clone().float())
        # The texel grid of an environment of this size (its one definition: renderer/environment.py).
        dirs, solid_angle = Environment(np.zeros((height, width, 3), np.float32)).texel_directions()
        self.register_buffer("directions", torch.from_numpy(dirs.reshape(-1, 3)).float())
        self.register_buffer("solid_angle", torch.from_numpy(solid_angle.reshape(-1)).float())
        self.register_buffer("lut", brdf_table())
        # The narrowest specular lobe, in texels (a texel spans pi / height): below it a lower roughness
        # changes nothing, so the fit cannot tell a glaze from a satin finish there.
        self.min_lobe_cos = math.cos(sharpest_lobe_texels * math.pi / height)
        if light_lobes:
            self._add_light_lobes(light_lobes, log_radiance)

    def _add_light_lobes(self, count: int, log_radiance: torch.Tensor) -> None:
        """`count` lobes spread over the upper hemisphere (one: the zenith), each about 30 degrees wide,
        its peak as bright as the panorama's median: a start the fit moves from, not a guess."""
        golden = math.pi * (3.0 - math.sqrt(5.0))
        axes = []
        for k in range(count):
            z = 1.0 - (k + 0.5) / count * 0.7 if count > 1 else 1.0  # elevations from about 90 to 17 degrees
            r = math.sqrt(max(0.0, 1.0 - z * z))
            axes.append((r * math.cos(k * golden), r * math.sin(k * golden), z))
        peak = log_radiance.reshape(-1, 3).median(0).values.float()
        self.lobe_axes = torch.nn.Parameter(torch.tensor(axes, dtype=torch.float32))
        self.lobe_log_amplitude = torch.nn.Parameter(peak[None].repeat(count, 1))
        self.lobe_log_sharpness = torch.nn.Parameter(torch.full((count,), math.log(8.0)))
        # No narrower than the texel spacing: a narrower lobe would fall between texel centres.
        self.max_lobe_sharpness = 2.0 / (1.0 - math.cos(math.pi / log_radiance.shape[0]))

    @classmethod
    def from_environment(cls, environment: Environment, height: int = 16, sharpest_lobe_texels: float = 1.0,
                         light_lobes: int = 0, smoothness_scale: float = 0.0,
                         camera_response: str = "aces") -> "PanoramaLighting":
        """Area-average `environment` down to height x 2 height texels."""
        mean = _area_mean(environment.radiance, environment, height)
        return cls(torch.from_numpy(np.log(np.maximum(mean, 1e-4))), sharpest_lobe_texels, light_lobes, smoothness_scale,
                   camera_response)

    @classmethod
    def from_capture_lighting(cls, lighting, height: int = 16, sharpest_lobe_texels: float = 1.0,
                              light_lobes: int = 0, smoothness_scale: float = 0.0) -> "PanoramaLighting":
        """From a capture's estimate (capture_lighting.CaptureLighting): starts as its filled panorama
        and keeps what the photos saw as an observation (`observation_loss`); clipped texels are
        lower bounds only."""
        panorama = cls.from_environment(lighting.environment, height, sharpest_lobe_texels, light_lobes, smoothness_scale,
                                        lighting.config.response)
        env = lighting.environment
        seen = (lighting.observed > 0).astype(np.float64)
        clipped = seen * lighting.clipped
        seen_share = _area_mean(seen[..., None], env, height)[..., 0]
        clipped_share = _area_mean(clipped[..., None], env, height)[..., 0] / np.maximum(seen_share, 1e-9)
        observed_mean = _area_mean(env.radiance * seen[..., None], env, height) / np.maximum(seen_share, 1e-9)[..., None]
        panorama.register_buffer("observed_log", torch.from_numpy(np.log(np.maximum(observed_mean, 1e-4))).float())
        panorama.register_buffer("seen_share", torch.from_numpy(seen_share).float())
        panorama.register_buffer("clipped_share", torch.from_numpy(np.clip(clipped_share, 0.0, 1.0)).float())
        return panorama

    def observation_loss(self) -> torch.Tensor:
        """How far the panorama is from what the photos' backgrounds saw: L1 in log radiance on seen
        texels (weighted by how much of each was seen), and for clipped ones only when below the
        clipped value (the light there was at least that bright)."""
        if not hasattr(self, "observed_log"):
            return self.log_radiance.new_zeros(())
        log_total = self.log_radiance if not self.light_lobes else self.radiance.clamp(min=1e-6).log()
        difference = log_total - self.observed_log
        unclipped = (1.0 - self.clipped_share)[..., None]
        per_texel = unclipped * difference.abs() + (1.0 - unclipped) * (-difference).clamp(min=0.0)
        weight = self.seen_share[..., None]
        return (weight * per_texel).sum() / weight.sum().clamp(min=1e-6) / 3.0

    def smoothness_loss(self) -> torch.Tensor:
        """Total variation of the log radiance (wrapping in longitude): unseen light stays plausible.
        The compact lights' lobes are not part of it.

        With a `smoothness_scale` s the variation is heavy-tailed: a step d in log radiance costs
        s * log(1 + |d| / s), as |d| below s and far less above it. Plain total variation prices a
        small bright source (a sun no photo saw, 4-5 in log contrast to the sky around it) at its full
        contrast, so the fit spreads it into a low, broad glow; real skies are smooth almost
        everywhere with a few sharp edges, the statistics a heavy tail describes."""
        scale = self.smoothness_scale

        def cost(step: torch.Tensor) -> torch.Tensor:
            return scale * torch.log1p(step.abs() / scale) if scale > 0 else step.abs()

        x = self.log_radiance
        return cost(x - x.roll(1, dims=1)).mean() + cost(x[1:] - x[:-1]).mean()

    def neutrality_loss(self) -> torch.Tensor:
        """How far the light's colour is from grey where no photo saw it: the L1 deviation of each
        texel's log radiance from its mean over the channels, weighted by how little of the texel was
        seen (and, for the compact lights, which no photo saw, of their amplitude). Without it the fit
        may colour the unseen sky after the object (a yellow mug under a yellow sky) and the albedo
        the other way; in every environment at hand the unseen upper sky is as neutral as the seen
        ground or bluer (README)."""
        x = self.log_radiance
        deviation = (x - x.mean(dim=-1, keepdim=True)).abs().mean(-1)
        unseen = 1.0 - self.seen_share if hasattr(self, "seen_share") else torch.ones_like(deviation)
        loss = (unseen * deviation).sum() / unseen.sum().clamp(min=1e-6)
        if self.light_lobes:
            a = self.lobe_log_amplitude
            loss = loss + (a - a.mean(dim=-1, keepdim=True)).abs().mean()
        return loss

    @property
    def light_lobes(self) -> int:
        return self.lobe_axes.shape[0] if hasattr(self, "lobe_axes") else 0

    @property
    def radiance(self) -> torch.Tensor:
        if not self.light_lobes:
            return self.log_radiance.exp()
        return self.log_radiance.exp() + self.lobe_radiance().reshape(self.log_radiance.shape)

    def lobe_radiance(self) -> torch.Tensor:
        """(texels, 3): the compact lights on the panorama's texels, each lobe's sampled values scaled
        so that their sum over solid angle is its exact integral (no energy gained or lost as a narrow
        lobe moves between texel centres)."""
        axes = self.lobe_axes / self.lobe_axes.norm(dim=-1, keepdim=True).clamp(min=1e-6)
        sharpness = self.lobe_log_sharpness.exp().clamp(0.5, self.max_lobe_sharpness)
        shape = torch.exp(sharpness[:, None] * (axes @ self.directions.T - 1.0))  # (lobes, texels)
        exact = 2.0 * math.pi * (1.0 - torch.exp(-2.0 * sharpness)) / sharpness
        shape = shape * (exact / (shape * self.solid_angle).sum(-1).clamp(min=1e-12))[:, None]
        return shape.T @ self.lobe_log_amplitude.exp()

    def environment(self, name: str = "as photographed (refined)") -> Environment:
        return Environment(self.radiance.detach().cpu().numpy().astype(np.float32), name=name)

    # The lighting interface of split_sum_shading.shade.
    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        cosine = (normals @ self.directions.T).clamp(min=0.0) * self.solid_angle
        return cosine @ self.radiance.reshape(-1, 3) / math.pi

    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        alpha = roughness.clamp(0.0, 1.0) ** 2
        sharpness = 1.0 / (2.0 * alpha * alpha).clamp(min=1e-6)
        sharpness = sharpness.clamp(max=2.0 / (1.0 - self.min_lobe_cos))  # no narrower than a texel
        d = directions / directions.norm(dim=-1, keepdim=True).clamp(min=1e-12)
        weights = torch.exp(sharpness[:, None] * ((d @ self.directions.T) - 1.0)) * self.solid_angle
        return weights @ self.radiance.reshape(-1, 3) / weights.sum(-1, keepdim=True).clamp(min=1e-12)

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return lut_lookup(self.lut, n_dot_v, roughness)


def _area_mean(values: np.ndarray, environment: Environment, height: int) -> np.ndarray:
    """(H, W, C) values of an environment's texels averaged by solid angle into height x 2 height bins."""
    h, w = values.shape[:2]
    rows, cols = height, 2 * height
    _, solid_angle = environment.texel_directions()
    bin_row = (np.arange(h) * rows) // h
    bin_col = (np.arange(w) * cols) // w
    bins = (bin_row[:, None] * cols + bin_col[None, :]).ravel()
    total = np.bincount(bins, solid_angle.ravel(), rows * cols)
    weighted = values.astype(np.float64) * solid_angle[..., None]
    mean = np.stack([np.bincount(bins, weighted[..., c].ravel(), rows * cols) for c in range(values.shape[2])], 1)
    return (mean / np.maximum(total, 1e-12)[:, None]).reshape(rows, cols, values.shape[2])
