"""The LIRM network: shapes, the hexa-plane query rule, NDE lookup, the update loop's constant size
and memory, and clear errors for bad input."""

from __future__ import annotations

import math

import pytest
import torch

from lirm.engine.errors import LirmUserError
from lirm.engine.model.config import PRESETS, preset
from lirm.engine.model.hexaplane import query_planes, query_planes_reference
from lirm.engine.model.lirm import LIRM, ViewBatch
from lirm.engine.model.nde import query_nde, reflect


def views(config, v=4, b=1, seed=0, size=None):
    g = torch.Generator().manual_seed(seed)
    s = size or config.image_size
    return ViewBatch(torch.rand(b, v, 3, s, s, generator=g), torch.rand(b, v, 3, s, s, generator=g),
                     torch.randn(b, v, 6, s, s, generator=g))


@pytest.fixture(scope="module")
def tiny():
    torch.manual_seed(0)
    return LIRM(preset("tiny")).eval()


def test_presets_match_the_paper_sizes():
    p = PRESETS["paper"]
    assert (p.depth, p.width, p.heads, p.width // p.heads) == (24, 1024, 16, 64)
    assert (p.plane_tokens, p.plane_channels, p.plane_resolution) == (48, 64, 384)
    assert (p.nde_tokens, p.nde_panoramas, p.nde_resolution) == (32, 4, 128)
    assert (p.image_size, p.patch, p.num_planes) == (512, 8, 6)
    with pytest.raises(ValueError, match="tiny"):
        preset("huge")


def test_update_decode_shapes_and_constant_token_counts(tiny):
    c = tiny.config
    state = tiny.initial_state()
    with torch.no_grad():
        for m in range(3):
            state = tiny.update(state, views(c, v=1 + m, seed=m))  # any number of views per update
            assert state.plane_tokens.shape == (1, c.num_plane_tokens, c.width)
            assert state.nde_tokens.shape == (1, c.num_nde_tokens, c.width)
        field = tiny.decode(state)
    assert state.updates == 3
    assert field.planes.shape == (1, 6, c.plane_channels, c.plane_resolution, c.plane_resolution)
    assert field.panoramas.shape == (1, c.nde_channels, c.nde_panoramas, c.nde_resolution, c.nde_resolution)
    pts = torch.rand(1, 50, 3) * 2 - 1
    sample = field.sample(pts, view_dirs=torch.nn.functional.normalize(torch.randn(1, 50, 3), dim=-1))
    assert sample.sdf.shape == (1, 50) and sample.albedo.shape == (1, 50, 3) and sample.colour.shape == (1, 50, 3)
    assert torch.allclose(sample.normal.norm(dim=-1), torch.ones(1, 50), atol=1e-5)
    assert ((sample.albedo > 0) & (sample.albedo < 1)).all()


def test_an_untrained_field_starts_as_the_sdf_prior_sphere(tiny):
    field = tiny.decode(tiny.initial_state())
    pts = torch.tensor([[[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]]])
    with torch.no_grad():
        head = tiny.heads.sdf(field.features(pts))[..., 0]
        s = field.sdf(pts)
    # s = MLP_s(f) + ||x|| - 0.1 R
    torch.testing.assert_close(s - head, torch.tensor([[-0.1, 0.8]]))


def test_hexa_plane_query_uses_the_half_space_of_the_third_axis():
    c, h = 2, 8
    planes = torch.zeros(1, 6, c, h, h)
    for k in range(6):
        planes[:, k] = k + 1.0  # constant planes: the feature tells which plane was read
    pts = torch.tensor([[[0.2, 0.3, 0.5], [0.2, 0.3, -0.5], [0.2, -0.3, 0.5], [-0.2, 0.3, 0.5]]])
    f = query_planes(planes, pts, radius=1.0)
    xy, xz, yz = f[0, :, 0], f[0, :, c], f[0, :, 2 * c]
    assert xy.tolist() == [1.0, 2.0, 1.0, 1.0]  # z >= 0 -> xy+, z < 0 -> xy-
    assert xz.tolist() == [3.0, 3.0, 4.0, 3.0]  # sign of y
    assert yz.tolist() == [5.0, 5.0, 5.0, 6.0]  # sign of x
    tri = query_planes(planes[:, :3], pts, radius=1.0)  # the tri-plane variant reads one plane per axis
    assert tri.shape == (1, 4, 3 * c)


def test_hexa_plane_bilinear_coordinates():
    # A plane whose feature is its column's x coordinate: reading it returns the point's x.
    h = 64
    xs = (torch.arange(h) + 0.5) / h * 2 - 1
    plane = xs.view(1, 1, 1, h).expand(1, 6, 1, h, h).clone()
    pts = torch.tensor([[[0.25, -0.4, 0.1], [-0.6, 0.2, -0.3]]])
    f = query_planes(plane, pts, radius=1.0)
    torch.testing.assert_close(f[0, :, 0], pts[0, :, 0], atol=1e-5, rtol=0)  # xy plane, column = x


def test_hexa_plane_query_reads_one_half_per_axis_as_the_reference_reads_both():
    generator = torch.Generator().manual_seed(0)
    planes = torch.randn(2, 6, 4, 16, 16, generator=generator, requires_grad=True)
    pts = torch.rand(2, 3000, 3, generator=generator) * 2.4 - 1.2  # beyond the planes' edges too
    pts[0, :50, 2] = 0.0  # on the plane between two halves
    pts[0, 50:100, 0] = torch.linspace(-1.0, 1.0, 50)  # along an axis, to both outer edges
    fast = query_planes(planes, pts, radius=1.0)
    reference = query_planes_reference(planes, pts, radius=1.0)
    torch.testing.assert_close(fast, reference, atol=1e-5, rtol=0)
    g_fast, = torch.autograd.grad((fast * fast.cos()).sum(), planes)
    g_reference, = torch.autograd.grad((reference * reference.cos()).sum(), planes)
    torch.testing.assert_close(g_fast, g_reference, atol=1e-4, rtol=1e-4)


def test_a_field_reads_its_planes_again_after_they_change_in_place(tiny):
    field = tiny.decode(tiny.initial_state())
    pts = torch.tensor([[[0.3, -0.2, 0.4], [-0.5, 0.1, -0.2]]])
    planes = field.planes.detach().clone()
    field.planes = planes
    before = field.features(pts).clone()
    with torch.no_grad():
        planes.add_(1.0)  # what an optimiser step does to a refined field's planes
    torch.testing.assert_close(field.features(pts), before + 1.0)


def test_nde_lookup_follows_the_reflection_direction_and_rho():
    n, hgt, wid = 2, 16, 32
    theta = (torch.arange(hgt) / (hgt - 1)) * math.pi  # align_corners=True: rows at 0..pi
    pano = torch.zeros(1, 2, n, hgt, wid)
    pano[0, 0] = torch.cos(theta).view(1, hgt, 1)  # channel 0 = cos(theta) = l_z
    pano[0, 1, 1] = 1.0  # channel 1 = which panorama
    d = torch.nn.functional.normalize(torch.tensor([[[0.3, 0.4, 0.5], [0.0, 0.6, -0.8]]]), dim=-1)
    out = query_nde(pano, d, rho=torch.tensor([[0.0, 1.0]]))
    torch.testing.assert_close(out[0, :, 0], d[0, :, 2], atol=0.02, rtol=0)
    assert out[0, :, 1].tolist() == [0.0, 1.0]
    v = torch.tensor([[[0.0, 0.0, -1.0]]])
    nrm = torch.nn.functional.normalize(torch.tensor([[[0.0, 1.0, 1.0]]]), dim=-1)
    torch.testing.assert_close(reflect(v, nrm), torch.tensor([[[0.0, 1.0, 0.0]]]), atol=1e-6, rtol=0)


def test_the_state_keeps_nothing_from_earlier_updates(tiny):
    """What an update hands on is fixed-size token tensors and no autograd history; peak memory per
    update is measured by the model benchmark (issue 4), not here."""
    c = tiny.config
    state = tiny.initial_state()
    sizes = []
    with torch.no_grad():
        for m in range(8):
            state = tiny.update(state, views(c, v=2 + m % 3, seed=m))
            sizes.append(state.plane_tokens.nbytes + state.nde_tokens.nbytes)
            assert state.plane_tokens.grad_fn is None and state.nde_tokens.grad_fn is None
    assert len(set(sizes)) == 1
    # With gradients (training), the graph of one update reaches back only through the state tokens.
    tiny.train()
    try:
        s1 = tiny.update(tiny.initial_state(), views(c, v=2))
        names = set()
        stack = [s1.plane_tokens.grad_fn]
        while stack:
            fn = stack.pop()
            if fn is None or fn in names:
                continue
            names.add(fn)
            stack.extend(f for f, _ in fn.next_functions)
        assert len(names) > 10  # a real graph exists while training
    finally:
        tiny.eval()


def test_bad_input_gives_clear_errors(tiny):
    c = tiny.config
    state = tiny.initial_state()
    good = views(c, v=2)
    with pytest.raises(LirmUserError, match="at least one view"):
        tiny.update(state, ViewBatch(good.image[:, :0], good.image_bg[:, :0], good.plucker[:, :0]))
    with pytest.raises(LirmUserError, match="mismatched"):
        tiny.update(state, ViewBatch(good.image, good.image_bg[:, :1], good.plucker))
    bad = good.image.clone()
    bad[0, 0, 0, 0, 0] = float("nan")
    with pytest.raises(LirmUserError, match="NaN"):
        tiny.update(state, ViewBatch(bad, good.image_bg, good.plucker))
    with pytest.raises(LirmUserError, match="multiple"):
        tiny.update(state, views(c, v=1, size=60))
    other = LIRM(preset("tiny", planes="tri"))
    with pytest.raises(LirmUserError, match="different model"):
        other.update(state, good)
    with pytest.raises(LirmUserError, match="different model"):
        other.decode(state)
