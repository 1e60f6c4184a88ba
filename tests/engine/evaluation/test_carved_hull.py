"""The carved visual hull: a reconstructor without learning whose shape and colour come only from the
views it is handed, so that more (or better chosen) views must give a better reconstruction."""

from __future__ import annotations

import numpy as np
import torch

from lirm.engine.cameras import orbit_camera
from lirm.engine.evaluation.carved_hull import CarvedHull, HullField
from lirm.engine.evaluation.evaluate import EvalConfig, evaluate_heldout
from lirm.engine.evaluation.heldout_sets import synthetic_heldout
from lirm.engine.model.lirm import ViewBatch

RADIUS = 0.5
RED, BLUE = np.array([0.9, 0.1, 0.1]), np.array([0.1, 0.2, 0.9])
ENVIRONMENT = np.array([0.3, 0.6, 0.4])


def _sphere_views(angles: list[tuple[float, float]], size: int = 48, tight: bool = True) -> ViewBatch:
    """Exact views of a sphere at the origin, red where x > 0 and blue where x < 0: masked image on
    white, the environment behind. `tight`: each view is a crop just holding the sphere, as the
    capture pipeline cuts photos (so what lies beyond the crop is background)."""
    images, backgrounds, pluckers = [], [], []
    for azimuth, elevation in angles:
        camera = orbit_camera(azimuth, elevation, 2.6, 4 * size, 4 * size, 50.0)
        if tight:
            xy, _ = camera.project(np.array([[0.0, 0.0, 0.0]]))
            half = 1.15 * RADIUS * camera.fx / 2.6
            camera = camera.crop_resize(xy[0, 0] - half, xy[0, 1] - half, 2 * half, 2 * half, size, size)
        else:
            camera = camera.resized(size, size)
        plucker = camera.plucker()
        d, m = plucker[..., :3].astype(np.float64), plucker[..., 3:].astype(np.float64)
        hit = np.linalg.norm(m, axis=-1) < RADIUS
        o = camera.center
        t = -(d @ o) - np.sqrt(np.maximum(RADIUS**2 - np.linalg.norm(m, axis=-1) ** 2, 0.0))
        x = o[0] + t * d[..., 0]
        colour = np.where((x > 0)[..., None], RED, BLUE)
        images.append(np.where(hit[..., None], colour, 1.0))
        backgrounds.append(np.where(hit[..., None], colour, ENVIRONMENT))
        pluckers.append(plucker)
    return ViewBatch.from_arrays(np.stack(images), np.stack(backgrounds), np.stack(pluckers))


def _sdf_error(field: HullField) -> float:
    """Mean |SDF| on the true sphere."""
    rng = np.random.default_rng(0)
    p = rng.normal(size=(2000, 3))
    p = RADIUS * p / np.linalg.norm(p, axis=1, keepdims=True)
    return float(field.sdf(torch.from_numpy(p.astype(np.float32))[None]).abs().mean())


def _colour_at(field: HullField, point) -> np.ndarray:
    p = torch.tensor([[point]], dtype=torch.float32)
    return field.sample(p, torch.tensor([[[0.0, 0.0, -1.0]]])).colour[0, 0].numpy()


RING = [(a, e) for e in (0.0, 35.0) for a in range(0, 360, 45)] + [(0.0, 80.0), (180.0, -60.0)]


def test_many_views_carve_the_sphere_and_colour_both_sides():
    hull = CarvedHull(image_size=48)
    state = hull.update(hull.initial_state(1), _sphere_views(RING))
    field = hull.decode(state)
    voxel = 2.0 / hull.config.resolution
    assert _sdf_error(field) < 1.5 * voxel
    assert float(field.sdf(torch.tensor([[[0.0, 0.0, 0.0]]]))) < -0.3  # solid inside
    # Beyond the crops is background: the corners of the domain are carved although no crop shows them.
    assert float(field.sdf(torch.tensor([[[0.85, 0.0, 0.0], [0.0, -0.6, 0.5]]])).min()) > 0.1
    np.testing.assert_allclose(_colour_at(field, [RADIUS, 0.0, 0.0]), RED, atol=0.08)
    np.testing.assert_allclose(_colour_at(field, [-RADIUS, 0.0, 0.0]), BLUE, atol=0.08)
    sample = field.sample(torch.tensor([[[RADIUS, 0.0, 0.0]]]))
    assert sample.colour is None and float(sample.roughness) == 0.5 and float(sample.metallic) == 0.0
    assert float(sample.albedo[0, 0, 0]) < RED[0]  # albedo is linear, the radiance stays sRGB
    assert float(sample.normal[0, 0, 0]) > 0.9  # outward on the +x side


def test_quality_follows_the_views_it_is_given():
    """The reason it exists: what no view saw, it does not know; adding the views that see it helps."""
    hull = CarvedHull(image_size=48)
    front = hull.update(hull.initial_state(1), _sphere_views([(80.0, 10.0), (100.0, 30.0)]))  # from +x only
    field = hull.decode(front)
    # The far side is unseen: its colour is a guess from the nearest seen part (red), and its shape is
    # only what two silhouettes carve, a long way from the sphere.
    assert np.abs(_colour_at(field, [-RADIUS, 0.0, 0.0]) - BLUE).max() > 0.3
    seen_from_front = _sdf_error(field)
    both = hull.update(front, _sphere_views([(260.0, 10.0), (280.0, 30.0), (0.0, 20.0), (180.0, 20.0)]))
    field = hull.decode(both)
    np.testing.assert_allclose(_colour_at(field, [-RADIUS, 0.0, 0.0]), BLUE, atol=0.1)
    assert _sdf_error(field) < 0.5 * seen_from_front
    # Constant memory: the state does not grow with updates.
    assert both.colour_sum.shape == front.colour_sum.shape and both.occupancy.shape == front.occupancy.shape


def test_views_without_the_object_change_nothing_and_nothing_seen_is_a_speck():
    hull = CarvedHull(image_size=16)
    empty = hull.decode(hull.initial_state(1))
    assert float(empty.sdf(torch.zeros(1, 1, 3))) < 0 and float(empty.sdf(torch.tensor([[[0.2, 0.0, 0.0]]]))) > 0
    white = np.ones((1, 16, 16, 3))
    nothing = ViewBatch.from_arrays(white, np.broadcast_to(ENVIRONMENT, (1, 16, 16, 3)),
                                    orbit_camera(0, 20, 2.6, 16, 16, 50.0).plucker()[None])
    state = hull.update(hull.initial_state(1), nothing)
    assert state.occupancy is None and state.updates == 1


def test_scored_on_heldout_objects_it_improves_with_every_update(renderer):
    objects = synthetic_heldout(renderer, 2, 48, surface_points=2000)
    config = EvalConfig(updates=3, output_views=2, mesh_resolution=48, chamfer_points=2000)
    rows = evaluate_heldout(CarvedHull(image_size=48), objects, config).rows
    assert rows[2].chamfer < rows[0].chamfer and rows[2].psnr > rows[0].psnr
    assert rows[2].chamfer < 0.08  # the silhouettes of 12 views pin the shape down


def _panel_views(angles: list[tuple[float, float]], half: float, offset: float, size: int = 64):
    """Cameras and exact masks of a square panel of zero thickness in the plane y = `offset`,
    |x|, |z| <= `half` (a card, a leaf, the glTF set's NormalTangentTest)."""
    cameras, masks = [], []
    for azimuth, elevation in angles:
        camera = orbit_camera(azimuth, elevation, 2.6, size, size, 50.0)
        plucker = camera.plucker().astype(np.float64)
        d, o = plucker[..., :3], camera.center
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (offset - o[1]) / d[..., 1]
        x, z = o[0] + t * d[..., 0], o[2] + t * d[..., 2]
        mask = (t > 0) & (np.abs(x) <= half) & (np.abs(z) <= half)
        if mask.sum() >= 20:  # a view edge-on sees nothing of it
            cameras.append(camera)
            masks.append(mask)
    return cameras, masks


def test_the_footprint_carve_keeps_parts_thinner_than_a_voxel():
    """A centre test carves away a panel thinner than a voxel (its voxels' centres lie off the plane
    and project beside its silhouette in oblique views); the footprint carve, which the refinement's
    start and sampling bounds use, keeps the voxels the panel passes through and stays a slab."""
    angles = [(a, e) for e in (20.0, 40.0) for a in range(10, 360, 45)]
    voxel = 2.0 / 32
    cameras, masks = _panel_views(angles, half=0.4, offset=0.02 * voxel)
    assert len(cameras) >= 12
    images = [np.zeros(m.shape + (3,)) for m in masks]
    grid = np.linspace(-0.4, 0.4, 41)
    points = np.stack(np.meshgrid(grid, [0.02 * voxel], grid, indexing="ij"), -1).reshape(-1, 3)
    cells = np.clip(((points + 1.0) / voxel).astype(int), 0, 31)

    def kept(footprint: bool) -> tuple[float, int]:
        hull = CarvedHull(image_size=64, resolution=32, footprint=footprint)
        occupancy = hull.update_known(hull.initial_state(1), cameras, images, masks).occupancy
        thickness = int(occupancy.any(axis=(0, 2)).sum())  # voxel layers along y holding anything
        return float(occupancy[cells[:, 0], cells[:, 1], cells[:, 2]].mean()), thickness

    centre_share, _ = kept(False)
    footprint_share, thickness = kept(True)
    assert centre_share < 0.5
    assert footprint_share > 0.99  # a corner cell of a grazing view may go: the masks are read at pixel centres
    assert thickness <= 8  # a slab (the ball it was carved from spans 32 layers)
