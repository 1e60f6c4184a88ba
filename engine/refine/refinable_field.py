"""The field a refinement optimises: the decoded LIRM field's own parts (hexa-planes, NDE panoramas,
the PBR and radiance heads) as trainable parameters.

It is the same field every other part reads (model/field.py's Field); only where its planes come from
differs: optimised per scene instead of predicted by the transformer. The planes may be resampled to
a higher resolution than the decoder gives, for detail the prior cannot predict.
"""

from __future__ import annotations

import copy

import torch
import torch.nn.functional as F
from torch import nn

from lirm.engine.model.config import LIRMConfig
from lirm.engine.model.field import Field, FieldHeads


class RefinableField(nn.Module):
    def __init__(self, config: LIRMConfig, heads: FieldHeads, planes: torch.Tensor, panoramas: torch.Tensor | None):
        super().__init__()
        self.config = config
        self.heads = heads
        self.planes = nn.Parameter(planes.detach().clone().float())
        self.panoramas = None if panoramas is None else nn.Parameter(panoramas.detach().clone().float())
        self.fitted_beta: float | None = None  # set by the refiner: the beta of the state it keeps (Field.fitted_beta)

    @classmethod
    def from_field(cls, field: Field) -> "RefinableField":
        """A trainable copy of a decoded field (its heads copied too: the model is never touched)."""
        heads = copy.deepcopy(field.heads).float()
        for p in heads.parameters():
            p.requires_grad_(True)
        return cls(field.config, heads, field.planes, field.panoramas)

    @property
    def resolution(self) -> int:
        return int(self.planes.shape[-1])

    def field(self) -> Field:
        """The current field, differentiable with respect to this module's parameters."""
        return Field(self.config, self.heads, self.planes, self.panoramas)

    def frozen_field(self) -> Field:
        """A detached copy of the current field: what is saved, rendered and exported."""
        heads = copy.deepcopy(self.heads)
        for p in heads.parameters():
            p.requires_grad_(False)
        panoramas = None if self.panoramas is None else self.panoramas.detach().clone()
        return Field(self.config, heads.eval(), self.planes.detach().clone(), panoramas, self.fitted_beta)

    @torch.no_grad()
    def resample_planes(self, resolution: int) -> None:
        """Bilinearly resample the planes to `resolution` per side (align_corners=False keeps the
        planes' outer edge at +-R, as query_planes reads them)."""
        if resolution == self.resolution:
            return
        b, p, c, h, w = self.planes.shape
        resized = F.interpolate(self.planes.detach().reshape(b * p, c, h, w), size=(resolution, resolution),
                                mode="bilinear", align_corners=False)
        self.planes = nn.Parameter(resized.reshape(b, p, c, resolution, resolution).contiguous())

    def load_snapshot(self, snapshot: dict[str, torch.Tensor]) -> None:
        """Put back a state_dict taken earlier (its planes may be of another resolution)."""
        with torch.no_grad():
            if snapshot["planes"].shape != self.planes.shape:
                self.planes = nn.Parameter(snapshot["planes"].clone())
            self.load_state_dict(snapshot)

    def snapshot(self) -> dict[str, torch.Tensor]:
        return {k: v.detach().clone() for k, v in self.state_dict().items()}


def fresh_field(config: LIRMConfig, resolution: int, seed: int = 0) -> RefinableField:
    """`--init scratch`: newly initialised heads and near-zero planes (the SDF starts as the s_bias
    sphere of radius 0.1 R); nothing learnt is used."""
    generator = torch.Generator().manual_seed(seed)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        heads = FieldHeads(config)
    planes = torch.randn(1, config.num_planes, config.plane_channels, resolution, resolution, generator=generator) * 0.01
    panoramas = None
    if config.colour == "nde":
        size = config.nde_resolution
        panoramas = torch.randn(1, config.nde_channels, config.nde_panoramas, size, size, generator=generator) * 0.01
    return RefinableField(config, heads, planes, panoramas)
