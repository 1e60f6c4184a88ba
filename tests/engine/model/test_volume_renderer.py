"""The volume renderer is right independently of learning: analytic SDFs (and one planted into the
real decoded field) render the correct silhouette, depth and normals; the occupancy grid skips most
samples without changing the image; numerical normals match analytic ones."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage

from lirm.engine.cameras import orbit_camera
from lirm.engine.model.analytic_fields import BoxField, SphereField, box_ray_hit, sphere_ray_hit
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.occupancy_grid import OccupancyConfig, OccupancyGrid
from lirm.engine.model.volume_renderer import (FITTED_SPACING_IN_BETAS, VolumeRenderConfig, as_fitted, numerical_normals,
                                               render_camera, render_rays)

SIZE = 64
CONFIG = VolumeRenderConfig()


@pytest.fixture(scope="module")
def camera():
    return orbit_camera(30.0, 25.0, 2.6, SIZE, SIZE, 45.0)


def _rays(camera):
    o, d = camera.pixel_rays()
    return torch.tensor(o.reshape(-1, 3), dtype=torch.float32), torch.tensor(d.reshape(-1, 3), dtype=torch.float32)


def _analytic_truth(field, camera):
    """(first-hit distance, hit mask, surface normal at the hit) per pixel."""
    o, d = _rays(camera)
    if isinstance(field, SphereField):
        t, hit = sphere_ray_hit(o, d, field.sphere_radius)
    else:
        t, hit = box_ray_hit(o, d, field.half)
    normal = torch.nn.functional.normalize(field.gradient(o + t[:, None] * d), dim=-1)
    z = t * (d @ torch.tensor(camera.c2w[:3, 2], dtype=torch.float32))
    return z.numpy().reshape(SIZE, SIZE), hit.numpy().reshape(SIZE, SIZE), normal.numpy().reshape(SIZE, SIZE, 3)


def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1.0, 1.0)))


@pytest.mark.parametrize("field", [SphereField(0.45), BoxField((0.4, 0.3, 0.2))], ids=["sphere", "box"])
def test_analytic_silhouette_depth_and_normals(field, camera):
    out = render_camera(field, camera, CONFIG)
    z, hit, normal = _analytic_truth(field, camera)
    # The SDF's signed distance along each pixel's ray decides clear cases; VolSDF's Laplace density
    # with beta = 1/250 makes rays that graze within a few beta of the surface opaque too.
    o, d = _rays(camera)
    t = torch.linspace(0, 1, 512)[None, :, None] * 5.2
    graze = field.sdf(o[:, None] + t * d[:, None]).min(dim=1).values.numpy().reshape(SIZE, SIZE)
    clear_miss = graze > 5 * CONFIG.beta
    assert (out["opacity"][hit] > 0.5).all()
    assert (out["opacity"][clear_miss] < 0.5).all()
    iou = (hit & (out["opacity"] > 0.5)).sum() / (hit | (out["opacity"] > 0.5)).sum()
    assert iou > 0.9, iou  # small image: the boundary ring is a large share
    inner = ndimage.binary_erosion(hit, iterations=1)
    depth_error = np.abs(out["depth"] - z)[inner]
    assert np.median(depth_error) < 0.005 and depth_error.max() < 0.02  # camera at 2.6: under 1%
    # Faces (not edges, where one pixel sees two faces)
    smooth = (_angle_deg(normal, np.roll(normal, 1, 0)) < 15) & (_angle_deg(normal, np.roll(normal, 1, 1)) < 15)
    flat = inner & ndimage.binary_erosion(smooth, iterations=1)
    for name in ("normal", "normal_numerical"):
        angles = _angle_deg(out[name], normal)[flat]
        assert np.median(angles) < 0.5 and np.percentile(angles, 95) < 2.0, (name, np.percentile(angles, 95))
    # Material maps read the pattern at the surface: metallic is 1 on +y, roughness ramps in x.
    surface = o.numpy().reshape(SIZE, SIZE, 3) + (z / (d.numpy() @ camera.c2w[:3, 2]).reshape(SIZE, SIZE))[..., None] * d.numpy().reshape(SIZE, SIZE, 3)
    sure = inner & (np.abs(surface[..., 1]) > 0.05)
    assert np.mean(np.abs(out["metallic"][sure] - (surface[..., 1][sure] >= 0))) < 0.02
    expected_roughness = field.pattern.roughness(torch.tensor(surface[inner]), 1.0).numpy()
    assert np.median(np.abs(out["roughness"][inner] - expected_roughness)) < 0.01


@pytest.mark.parametrize("field", [SphereField(0.45), BoxField((0.4, 0.3, 0.2))], ids=["sphere", "box"])
def test_occupancy_grid_skips_most_samples_without_changing_the_image(field, camera):
    plain = render_camera(field, camera, CONFIG)
    grid = OccupancyGrid.build(field, 1.0, CONFIG.beta, 2.0 / CONFIG.samples_per_ray, OccupancyConfig(resolution=128))
    pruned = render_camera(field, camera, CONFIG, grid)
    assert pruned.stats.skipped_fraction >= 0.8, pruned.stats.skipped_fraction
    for name in ("colour", "opacity"):
        assert np.abs(pruned[name] - plain[name]).max() < 1e-3, name
    # Material maps are divided by opacity; compare what was composited (premultiplied).
    premultiplied = [out["albedo"] * out["opacity"][..., None] for out in (pruned, plain)]
    assert np.abs(premultiplied[0] - premultiplied[1]).max() < 1e-3


def test_numerical_normals_match_analytic():
    g = torch.Generator().manual_seed(0)
    directions = torch.nn.functional.normalize(torch.randn(500, 3, generator=g), dim=-1)
    sphere = SphereField(0.5, normal_eps=2 * 2.0 / 128)  # 2 voxels of a 128^2 hexa-plane
    points = directions * 0.5
    assert _angle_deg(numerical_normals(sphere, points).numpy(), directions.numpy()).max() < 0.1  # float32 differences
    box = BoxField((0.4, 0.3, 0.2), normal_eps=0.01)
    face_points = torch.rand(500, 3, generator=g) * torch.tensor([0.6, 0.4, 0.0]) - torch.tensor([0.3, 0.2, -0.2])
    n = numerical_normals(box, face_points).numpy()
    assert _angle_deg(n, np.array([0.0, 0.0, 1.0])).max() < 0.01


def _planted_sphere_lirm(radius: float):
    """The real decoded field with an analytic SDF planted: the SDF head outputs a constant, so
    s(x) = c + ||x|| - 0.1 R is the sphere of radius 0.1 R - c."""
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).eval()
    last = model.heads.sdf[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(-(radius - model.config.sdf_bias_fraction * model.config.radius))
    state = model.initial_state(1)
    return model.decode(state)


def test_planted_sphere_in_the_decoded_field(camera):
    field = _planted_sphere_lirm(0.45)
    out = render_camera(field, camera, CONFIG)
    z, hit, normal = _analytic_truth(SphereField(0.45), camera)
    assert (out["opacity"][hit] > 0.5).all()
    inner = ndimage.binary_erosion(hit, iterations=1)
    assert np.median(np.abs(out["depth"] - z)[inner]) < 0.005
    # Numerical normals at 2 hexa-plane voxels recover the analytic sphere normals.
    assert np.percentile(_angle_deg(out["normal_numerical"], normal)[inner], 95) < 2.0
    assert np.isfinite(out["colour"]).all() and out["colour"].min() >= 0 and out["colour"].max() <= 1


def test_rendering_is_differentiable_in_the_planes(camera):
    field = _planted_sphere_lirm(0.45)
    field.planes.retain_grad()  # a non-leaf: the decoder made it
    o, d = _rays(camera)
    middle = slice(SIZE * SIZE // 2 - 128, SIZE * SIZE // 2 + 128)  # rows through the sphere
    out = render_rays(field, o[middle], d[middle], VolumeRenderConfig(samples_per_ray=32, stratified=True))
    assert out["opacity"].max() > 0.5
    (out["colour"].sum() + out["albedo"].sum() + out["normal_numerical"].sum()).backward()
    assert field.planes.grad is not None and field.planes.grad.abs().sum() > 0


def test_a_refined_field_renders_at_the_beta_it_was_fitted_at(camera):
    plain = SphereField(0.45)
    assert as_fitted(CONFIG, plain) is CONFIG  # no fitted beta: the model's own
    sharp = SphereField(0.45)
    sharp.fitted_beta = 1.0 / 500.0
    config = as_fitted(CONFIG, sharp)
    assert config.beta == pytest.approx(1.0 / 500.0)
    # dense enough that the sharp density's step falls within a few samples; a preview keeps its own
    assert 2.0 * sharp.radius / config.samples_per_ray <= FITTED_SPACING_IN_BETAS / 500.0 + 1e-9
    assert as_fitted(CONFIG, sharp, dense=False).samples_per_ray == CONFIG.samples_per_ray
    # Rendered at its own beta the coverage follows the true silhouette; at the softer 1/250 the
    # density reaches further out and rim pixels outside the sphere gather more opacity.
    _, hit, _ = _analytic_truth(sharp, camera)
    outside = ~ndimage.binary_dilation(hit, iterations=1) & ndimage.binary_dilation(hit, iterations=3)
    as_fitted_opacity = render_camera(sharp, camera, config)["opacity"]
    softer_opacity = render_camera(sharp, camera, CONFIG)["opacity"]
    assert as_fitted_opacity[outside].mean() < softer_opacity[outside].mean()
    assert np.abs(as_fitted_opacity - hit).mean() < np.abs(softer_opacity - hit).mean()
