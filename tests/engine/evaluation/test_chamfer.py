import numpy as np
import pytest

from lirm.engine.evaluation.chamfer import chamfer_distance, surface_samples


def test_chamfer_of_concentric_spheres_is_their_gap():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert chamfer_distance(d * 0.5, d[::-1] * 0.6) == pytest.approx(0.1, abs=0.01)
    assert chamfer_distance(d, d) == 0.0
    assert chamfer_distance(d, np.zeros((0, 3))) == float("inf")


def test_surface_samples_lie_on_the_triangles():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    points = surface_samples(vertices, np.array([[0, 1, 2]]), 500)
    assert points.shape == (500, 3)
    assert np.allclose(points[:, 2], 0) and np.all(points[:, 0] + points[:, 1] <= 1 + 1e-6)
