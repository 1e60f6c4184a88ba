"""A known environment held fixed, with the interface of the fittable PanoramaLighting: the oracle of
`lirm bench refine --lighting truth`, which measures what the capture's lighting estimate costs the
materials (the same refinement, lit by the renderer's own tables of the true environment)."""

from __future__ import annotations

import torch

from .split_sum_shading import SplitSumTables


class FixedLighting(torch.nn.Module):
    def __init__(self, tables: SplitSumTables, camera_response: str = "aces"):
        super().__init__()
        self.tables = tables  # on the refinement's device already: nothing here moves or learns
        # The tone curve the photos were taken through (camera_response.RESPONSES), as PanoramaLighting
        # carries it: the held-out views are rendered through the renderer's own display, ACES.
        self.camera_response = camera_response

    def observation_loss(self) -> torch.Tensor:
        return torch.zeros(())

    def smoothness_loss(self) -> torch.Tensor:
        return torch.zeros(())

    def prefiltered(self, directions: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return self.tables.prefiltered(directions, roughness)

    def irradiance_over_pi(self, normals: torch.Tensor) -> torch.Tensor:
        return self.tables.irradiance_over_pi(normals)

    def brdf(self, n_dot_v: torch.Tensor, roughness: torch.Tensor) -> torch.Tensor:
        return self.tables.brdf(n_dot_v, roughness)
