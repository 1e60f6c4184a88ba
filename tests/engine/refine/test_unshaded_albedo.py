import torch

from lirm.engine.refine.unshaded_albedo import MIN_POINTS, normal_explained_albedo


def _surface(count: int = 1000, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Normals all round a surface and two paints laid on it regardless of the normal (linear albedo)."""
    g = torch.Generator().manual_seed(seed)
    normal = torch.nn.functional.normalize(torch.randn(count, 3, generator=g), dim=-1)
    red = torch.rand(count, 1, generator=g) < 0.5
    paint = torch.where(red, torch.tensor([0.6, 0.08, 0.05]), torch.tensor([0.8, 0.75, 0.6]))
    return paint, normal


def test_shading_baked_into_the_albedo_is_what_the_term_sees():
    paint, normal = _surface()
    lit_from_above = 0.6 + 0.35 * normal[:, 2:3]  # the inputs' light, left in the albedo
    assert float(normal_explained_albedo(paint * lit_from_above, normal)) > 20 * float(normal_explained_albedo(paint, normal))


def test_the_term_removes_the_shading_and_keeps_the_paints():
    """Minimising it alone from a shaded albedo takes out what follows the normal and leaves the two
    paints as far apart as they were."""
    paint, normal = _surface()
    shaded = paint * (0.6 + 0.35 * normal[:, 2:3])
    log_albedo = shaded.log().clone().requires_grad_(True)
    optimiser = torch.optim.Adam([log_albedo], lr=0.01)
    for _ in range(300):
        loss = normal_explained_albedo(log_albedo.exp(), normal)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    albedo = log_albedo.detach().exp()
    assert float(normal_explained_albedo(albedo, normal)) < 0.02 * float(normal_explained_albedo(shaded, normal))
    red = paint[:, 1] < 0.5
    up, down = normal[:, 2] > 0.5, normal[:, 2] < -0.5
    # The same paint facing up and facing down: 2.6 x apart in red before, within 15% after
    ratio = lambda a, m: float(a[m & up, 0].mean() / a[m & down, 0].mean())  # noqa: E731
    assert ratio(shaded, red) > 2.0 and abs(ratio(albedo, red) - 1.0) < 0.15
    # The paints stay apart: the cream's green over the red's, as in the paint.
    contrast = lambda a: float(a[~red, 1].mean() / a[red, 1].mean())  # noqa: E731
    assert abs(contrast(albedo) / contrast(paint) - 1.0) < 0.15


def test_it_moves_the_albedo_and_not_the_normal():
    paint, normal = _surface()
    normal = normal.clone().requires_grad_(True)
    albedo = (paint * (0.6 + 0.35 * normal.detach()[:, 2:3])).requires_grad_(True)
    normal_explained_albedo(albedo, normal).backward()
    assert albedo.grad is not None and float(albedo.grad.abs().sum()) > 0
    assert normal.grad is None


def test_too_few_points_give_no_loss():
    paint, normal = _surface(MIN_POINTS - 1)
    assert float(normal_explained_albedo(paint * (0.5 + 0.4 * normal[:, 2:3]), normal)) == 0.0
