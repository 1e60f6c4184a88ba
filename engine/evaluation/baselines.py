"""Baselines scored with the same protocol as LIRM (issue 7): the untrained network of the same
architecture, and a trivial reconstructor, a sphere with the inputs' mean colour.

Both follow the progressive interface the evaluation drives (`initial_state`, `update`, `decode`), so
they see exactly the views LIRM sees, one input set at a time.

The sphere is the honest "no learning" floor: its radius is chosen so that it covers as many input
rays as the inputs have object pixels (a ray's distance from the centre is the norm of its Plücker
moment, so no camera model is needed), its albedo and radiance are the mean colour of the object
pixels seen so far, and its material is a plain dielectric (roughness 0.5, metallic 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
import torch.nn.functional as F

from lirm.engine.model.config import LIRMConfig
from lirm.engine.model.field import FieldSample
from lirm.engine.model.lirm import LIRM, ViewBatch
from lirm.renderer.tonemap import srgb_to_linear

BASELINE_ROUGHNESS = 0.5
BASELINE_METALLIC = 0.0
# A pixel of the masked input (object on white) is the object's when it equals the background image
# there (the object hides the environment) and is not the white fill itself.
SAME_PIXEL = 0.02
WHITE = 0.995


def untrained_model(config: LIRMConfig, seed: int = 0) -> LIRM:
    """The network of `config` at its initial weights (a fixed seed, the caller's RNG untouched)."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return LIRM(config).eval()


@dataclass(frozen=True)
class SphereBaselineConfig:
    image_size: int  # the side of the input views it is handed, as LIRM's config says
    name: str = "mean-colour sphere"
    radius: float = 1.0  # the bounding sphere the renderer marches in (LIRM's R)


@dataclass
class SphereState:
    colour_sum: torch.Tensor = field(default_factory=lambda: torch.zeros(3, dtype=torch.float64))
    object_pixels: int = 0
    all_pixels: int = 0
    distances: list[torch.Tensor] = field(default_factory=list)  # per update: every input ray's distance from the centre
    updates: int = 0


class MeanColourSphere:
    """The trivial reconstructor: a sphere of the inputs' mean colour and apparent size."""

    def __init__(self, image_size: int, radius: float = 1.0):
        self.config = SphereBaselineConfig(image_size=image_size, radius=radius)

    def initial_state(self, batch: int = 1) -> SphereState:
        if batch != 1:
            raise ValueError("the sphere baseline reconstructs one object at a time")
        return SphereState()

    def update(self, state: SphereState, views: ViewBatch) -> SphereState:
        image = views.image[0].permute(0, 2, 3, 1).double().cpu()  # (V, H, W, 3)
        background = views.image_bg[0].permute(0, 2, 3, 1).double().cpu()
        moment = views.plucker[0, :, 3:].permute(0, 2, 3, 1).double().cpu()
        on_object = ((image - background).abs().amax(-1) < SAME_PIXEL) & (image.amin(-1) < WHITE)
        return SphereState(colour_sum=state.colour_sum + image[on_object].sum(0),
                           object_pixels=state.object_pixels + int(on_object.sum()),
                           all_pixels=state.all_pixels + on_object.numel(),
                           distances=state.distances + [moment.norm(dim=-1).flatten()],
                           updates=state.updates + 1)

    def decode(self, state: SphereState) -> "SphereField":
        if state.object_pixels == 0:
            # Nothing seen: the smallest sphere, grey, so the scores stay defined and poor.
            return SphereField(0.05, torch.full((3,), 0.5), self.config.radius)
        colour = (state.colour_sum / state.object_pixels).float()
        fraction = state.object_pixels / state.all_pixels
        radius = float(torch.quantile(torch.cat(state.distances).float(), min(fraction, 1.0)))
        return SphereField(max(radius, 1e-3), colour, self.config.radius)


class SphereField:
    """An analytic field (the renderer's duck-typed Field interface): a sphere at the origin."""

    def __init__(self, sphere_radius: float, colour_srgb: torch.Tensor, bounds_radius: float = 1.0):
        self.sphere_radius = float(sphere_radius)
        self.colour = colour_srgb.float().clamp(0.0, 1.0)
        self.albedo = torch.from_numpy(srgb_to_linear(self.colour.numpy())).float()
        self.radius = float(bounds_radius)
        self.normal_eps = 1e-3

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return points.norm(dim=-1) - self.sphere_radius

    def sample(self, points: torch.Tensor, view_dirs: torch.Tensor | None = None) -> FieldSample:
        shape = points.shape[:-1]
        fill = lambda value: torch.full(shape, value, dtype=points.dtype, device=points.device)  # noqa: E731
        per_point = lambda v: v.to(points).expand(*shape, 3)  # noqa: E731
        return FieldSample(sdf=self.sdf(points), albedo=per_point(self.albedo), roughness=fill(BASELINE_ROUGHNESS),
                           metallic=fill(BASELINE_METALLIC), normal=F.normalize(points, dim=-1),
                           colour=None if view_dirs is None else per_point(self.colour))
