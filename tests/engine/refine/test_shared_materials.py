import torch

from lirm.engine.refine.shared_materials import like_albedo_targets, shared_albedo_loss, shared_material_loss


def _two_paints(count: int = 400) -> torch.Tensor:
    """Half the points a red paint, half a cream one, each with a little noise (linear albedo)."""
    g = torch.Generator().manual_seed(1)
    red = torch.tensor([0.6, 0.05, 0.04]) + 0.01 * torch.randn(count // 2, 3, generator=g)
    cream = torch.tensor([0.8, 0.7, 0.5]) + 0.01 * torch.randn(count // 2, 3, generator=g)
    return torch.cat([red, cream]).clamp(0.0, 1.0)


def test_what_a_few_points_say_reaches_their_paint_and_not_the_other():
    """Ten red points see a highlight (evidence for roughness 0.1), ten cream points are seen to be
    rough (0.6), ten red ones to be metal; every other point starts at 0.5 and dull. Under the term,
    the evidence reaches the rest of its own paint and not the other paint."""
    albedo = _two_paints()
    roughness = torch.full((400,), 0.5, requires_grad=True)
    metallic = torch.zeros(400, requires_grad=True)
    seen = torch.zeros(400, dtype=torch.bool)
    seen[:10] = True
    seen[200:210] = True
    red = torch.arange(400) < 200
    evidence = torch.where(red, torch.tensor(0.1), torch.tensor(0.6))
    optimiser = torch.optim.Adam([roughness, metallic], lr=0.02)
    for _ in range(300):
        loss = (shared_material_loss(albedo, roughness, metallic)
                + 0.05 * ((roughness - evidence)[seen] ** 2).sum() + 0.05 * ((metallic[:10] - 1.0) ** 2).sum())
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    r, m = roughness.detach(), metallic.detach()
    assert abs(float(r[10:200].mean()) - 0.1) < 0.05, float(r[10:200].mean())
    assert abs(float(r[210:].mean()) - 0.6) < 0.05, float(r[210:].mean())
    assert float(m[10:200].mean()) > 0.8 and float(m[200:].abs().max()) < 0.05


def test_the_targets_are_each_paints_own_mean():
    albedo = _two_paints()
    values = torch.cat([torch.full((200, 1), 0.2), torch.full((200, 1), 0.7)])
    values[0] = 1.0  # one outlier of the red paint moves the red target a little, the cream one not at all
    targets = like_albedo_targets(albedo, values)[:, 0]
    assert bool(((targets[1:200] > 0.2) & (targets[1:200] < 0.2 + 2 * 0.8 / 200)).all())
    assert torch.allclose(targets[200:], torch.tensor(0.7), atol=1e-4)


def test_one_point_gives_no_loss():
    assert float(shared_material_loss(torch.rand(1, 3), torch.rand(1), torch.rand(1))) == 0.0


def test_without_metallic_only_the_roughness_is_shared():
    albedo = _two_paints()
    roughness = torch.cat([torch.full((200,), 0.2), torch.full((200,), 0.7)])
    assert float(shared_material_loss(albedo, roughness, None)) < 1e-8
    metallic = torch.rand(400, generator=torch.Generator().manual_seed(0))
    assert float(shared_material_loss(albedo, roughness, metallic)) > 0.05


def test_the_kernel_width_says_which_albedos_are_one_paint():
    """Two creams a little apart (about 0.06 in the display-like space) are one paint to a wide
    kernel and two to a narrow one."""
    albedo = torch.cat([torch.full((50, 3), 0.50), torch.full((50, 3), 0.58)])
    roughness = torch.cat([torch.full((50, 1), 0.2), torch.full((50, 1), 0.6)])
    narrow = like_albedo_targets(albedo, roughness, sigma=0.01)[:, 0]
    wide = like_albedo_targets(albedo, roughness, sigma=0.5)[:, 0]
    assert torch.allclose(narrow[:50], torch.tensor(0.2), atol=1e-3) and torch.allclose(narrow[50:], torch.tensor(0.6), atol=1e-3)
    assert float((wide - 0.4).abs().max()) < 0.01


def test_the_shared_albedo_flattens_shading_within_a_paint_and_keeps_the_paints_apart():
    """A cream paint with a slow shading ramp left in it (0.70 to 0.76) and a red one: under the term
    alone the ramp flattens toward the cream's mean, and the red stays red."""
    ramp = torch.linspace(0.0, 0.06, 200)[:, None]
    cream = torch.tensor([0.70, 0.60, 0.45]) + ramp
    red = torch.tensor([0.6, 0.05, 0.04]).repeat(200, 1)
    albedo = torch.cat([cream, red]).requires_grad_(True)
    optimiser = torch.optim.SGD([albedo], lr=50.0)  # plain steps: Adam would blow up the red's ~0 gradients
    for _ in range(100):
        loss = shared_albedo_loss(albedo)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    fitted = albedo.detach()
    assert float(fitted[:200, 0].max() - fitted[:200, 0].min()) < 0.02  # the ramp flattened (from 0.06)
    assert abs(float(fitted[:200, 0].mean()) - 0.73) < 0.01
    assert torch.allclose(fitted[200:], torch.tensor([0.6, 0.05, 0.04]), atol=1e-3)
    assert float(shared_albedo_loss(torch.rand(1, 3))) == 0.0
