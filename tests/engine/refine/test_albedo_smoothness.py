from types import SimpleNamespace

import torch

from lirm.engine.refine.albedo_smoothness import albedo_difference
from lirm.engine.refine.objective import CURVATURE_STEP


class PaintedField:
    """A stand-in field whose albedo is a function of the point (the term only reads field.sample)."""

    def __init__(self, albedo_at):
        self.albedo_at = albedo_at

    def sample(self, points, view_dirs=None, materials=True):
        return SimpleNamespace(albedo=self.albedo_at(points))


RED, CREAM = torch.tensor([0.6, 0.08, 0.05]), torch.tensor([0.8, 0.75, 0.6])


def _surface_points(count: int = 2000) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    points = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1) * 0.5
    offsets = torch.randn(count, 3, generator=g) * CURVATURE_STEP
    return points, offsets


def test_grain_costs_far_more_than_a_painted_pattern():
    points, offsets = _surface_points()
    # Two paints in bands round the object: an edge every quarter of the height.
    bands = PaintedField(lambda p: torch.where((torch.floor(p[..., 2:3] * 4.0) % 2) == 0, RED, CREAM))
    # One paint, its brightness speckled by a grain finer than the step.
    grain = PaintedField(lambda p: CREAM * (0.85 + 0.15 * torch.sin(400.0 * p.sum(-1, keepdim=True))))
    plain = PaintedField(lambda p: CREAM.expand(*p.shape[:-1], 3))
    assert float(albedo_difference(plain, points, offsets)) == 0.0
    assert float(albedo_difference(grain, points, offsets)) > 4.0 * float(albedo_difference(bands, points, offsets))


def test_the_gradient_reaches_what_makes_the_albedo():
    points, offsets = _surface_points(200)
    frequency = torch.tensor(400.0, requires_grad=True)
    grain = PaintedField(lambda p: CREAM * (0.85 + 0.15 * torch.sin(frequency * p.sum(-1, keepdim=True))))
    albedo_difference(grain, points, offsets).backward()
    assert frequency.grad is not None and torch.isfinite(frequency.grad) and float(frequency.grad.abs()) > 0


def test_no_points_give_no_loss():
    plain = PaintedField(lambda p: CREAM.expand(*p.shape[:-1], 3))
    assert float(albedo_difference(plain, torch.zeros(0, 3), torch.zeros(0, 3))) == 0.0
