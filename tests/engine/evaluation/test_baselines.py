"""The baselines LIRM is scored against: the mean-colour sphere recovers a sphere's size and colour
from its silhouettes alone, and the untrained network is reproducible."""

from __future__ import annotations

import numpy as np
import torch

from lirm.engine.cameras import orbit_camera
from lirm.engine.evaluation.baselines import MeanColourSphere, untrained_model
from lirm.engine.evaluation.evaluate import EvalConfig, evaluate_heldout
from lirm.engine.evaluation.heldout_sets import synthetic_heldout
from lirm.engine.model.config import preset
from lirm.engine.model.lirm import ViewBatch
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera


def _sphere_views(radius: float, colour, size: int = 48) -> ViewBatch:
    """Exact views of a flat-coloured sphere at the origin: masked image on white, environment behind."""
    images, backgrounds, pluckers = [], [], []
    for k, (azimuth, elevation) in enumerate([(0, 10), (90, 30), (200, -5), (300, 60)]):
        camera = orbit_camera(azimuth, elevation, 2.6 + 0.3 * k, size, size, 40.0)
        plucker = camera.plucker()
        hit = np.linalg.norm(plucker[..., 3:], axis=-1) < radius
        environment = np.broadcast_to(np.array([0.3, 0.6, 0.9]), (size, size, 3))
        images.append(np.where(hit[..., None], colour, 1.0))
        backgrounds.append(np.where(hit[..., None], colour, environment))
        pluckers.append(plucker)
    return ViewBatch.from_arrays(np.stack(images), np.stack(backgrounds), np.stack(pluckers))


def test_sphere_baseline_recovers_size_and_mean_colour():
    baseline = MeanColourSphere(image_size=48)
    state = baseline.update(baseline.initial_state(1), _sphere_views(0.55, np.array([0.8, 0.4, 0.2])))
    field = baseline.decode(state)
    assert abs(field.sphere_radius - 0.55) < 0.02
    np.testing.assert_allclose(field.colour.numpy(), [0.8, 0.4, 0.2], atol=1e-5)
    # Albedo is linear, radiance stays display sRGB; the material is a plain dielectric.
    points = torch.tensor([[[field.sphere_radius, 0.0, 0.0], [0.0, 0.0, 0.2]]])
    sample = field.sample(points, torch.tensor([[[-1.0, 0.0, 0.0]] * 2]))
    assert abs(float(sample.sdf[0, 0])) < 1e-6 and float(sample.sdf[0, 1]) < 0
    assert float(sample.albedo[0, 0, 0]) < 0.8 and float(sample.roughness[0, 0]) == 0.5 and float(sample.metallic.max()) == 0
    # A second update with another sphere's views averages what was seen.
    state = baseline.update(state, _sphere_views(0.55, np.array([0.2, 0.4, 0.8])))
    np.testing.assert_allclose(baseline.decode(state).colour.numpy(), [0.5, 0.4, 0.5], atol=1e-5)


def test_sphere_baseline_renders_its_silhouette():
    baseline = MeanColourSphere(image_size=32)
    field = baseline.decode(baseline.update(baseline.initial_state(1), _sphere_views(0.5, np.array([0.1, 0.7, 0.3]), 32)))
    camera = orbit_camera(45, 20, 2.8, 32, 32, 40.0)
    out = render_camera(field, camera, VolumeRenderConfig(samples_per_ray=64, beta=0.01, numerical_normals=False))
    distance = np.linalg.norm(camera.plucker()[..., 3:], axis=-1)  # of each pixel's ray from the centre
    assert np.abs(out["colour"][distance < 0.45] - [0.1, 0.7, 0.3]).max() < 0.05
    assert np.abs(out["colour"][distance > 0.55] - 1.0).max() < 0.05  # white around it


def test_sphere_baseline_with_no_object_pixels_stays_defined():
    baseline = MeanColourSphere(image_size=16)
    white = np.ones((1, 16, 16, 3))
    views = ViewBatch.from_arrays(white, np.zeros((1, 16, 16, 3)), np.zeros((1, 16, 16, 6)))
    field = baseline.decode(baseline.update(baseline.initial_state(1), views))
    assert field.sphere_radius > 0 and torch.isfinite(field.colour).all()


def test_untrained_model_is_reproducible_and_leaves_the_rng_alone():
    torch.manual_seed(123)
    before = torch.rand(1)
    torch.manual_seed(123)
    a = untrained_model(preset("tiny"))
    after = torch.rand(1)
    b = untrained_model(preset("tiny"))
    assert torch.equal(before, after)
    for (name, p), q in zip(a.state_dict().items(), b.state_dict().values()):
        assert torch.equal(p, q), name


def test_baselines_go_through_the_same_evaluation(renderer):
    objects = synthetic_heldout(renderer, 1, 32, surface_points=500)
    config = EvalConfig(updates=2, render=VolumeRenderConfig(samples_per_ray=32, numerical_normals=False),
                        mesh_resolution=24, chamfer_points=500, output_views=2)
    sphere = evaluate_heldout(MeanColourSphere(32), objects, config)
    assert [r.update for r in sphere.rows] == [1, 2]
    for row in sphere.rows:
        # The sphere is fitted to the object's silhouettes, so its surface is near the true one.
        assert 5 < row.psnr < 40 and row.chamfer is not None and row.chamfer < 0.3


def test_input_sensitivity_tells_a_reader_of_inputs_from_a_prior(renderer):
    from lirm.engine.evaluation.input_sensitivity import input_sensitivity

    objects = synthetic_heldout(renderer, 2, 32, surface_points=300)
    sphere = input_sensitivity(MeanColourSphere(32), objects)
    assert sphere.pairs == 2 and sphere.albedo > 0.01 and sphere.sdf > 0.001  # colour and size follow the views

    class Prior:
        """Shows the same sphere whatever it is shown."""

        config = MeanColourSphere(32).config

        def initial_state(self, batch=1):
            return None

        def update(self, state, views):
            return None

        def decode(self, state):
            from lirm.engine.evaluation.baselines import SphereField

            return SphereField(0.5, torch.tensor([0.5, 0.4, 0.3]))

    prior = input_sensitivity(Prior(), objects)
    assert prior.albedo == 0 and prior.sdf == 0
