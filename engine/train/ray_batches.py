"""Supervision as rays: every pixel of the target views flattened with its ray and its targets, so
a training step renders a random subset (the paper supervises random crops; for rays through a
volume renderer any subset works the same way)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from lirm.engine.synth.object_views import ObjectViews


@dataclass
class RayTargets:
    origins: torch.Tensor  # (N, 3)
    directions: torch.Tensor  # (N, 3) unit
    colour: torch.Tensor  # (N, 3) display sRGB over white
    albedo: torch.Tensor  # (N, 3) linear albedo over white
    mask: torch.Tensor  # (N,)

    def __len__(self) -> int:
        return self.origins.shape[0]

    def subset(self, index: torch.Tensor) -> "RayTargets":
        return RayTargets(*(getattr(self, f)[index] for f in ("origins", "directions", "colour", "albedo", "mask")))

    @classmethod
    def from_views(cls, views: ObjectViews, indices: list[int] | None = None, device: str | torch.device = "cpu") -> "RayTargets":
        idx = list(range(len(views.cameras))) if indices is None else list(indices)
        rays = [views.cameras[i].pixel_rays() for i in idx]
        mask = views.mask[idx][..., None]

        def flat(a: np.ndarray) -> torch.Tensor:
            return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32).reshape(-1, a.shape[-1])).to(device)

        return cls(flat(np.stack([r[0] for r in rays])), flat(np.stack([r[1] for r in rays])), flat(views.image[idx]),
                   flat(views.albedo[idx] + (1.0 - mask)), flat(mask)[:, 0])
