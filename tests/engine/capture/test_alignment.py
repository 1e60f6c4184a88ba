"""Similarity alignment and pose-error metrics on synthetic cameras with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lirm.engine.cameras import Camera, orbit_cameras
from lirm.engine.capture.alignment import (
    apply_similarity,
    pose_errors,
    rotation_angle_deg,
    scene_size,
    similarity_align,
)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    return q


def _transform_cameras(cams: dict[str, Camera], s: float, R: np.ndarray, t: np.ndarray) -> dict[str, Camera]:
    out = {}
    for k, c in cams.items():
        c2w = np.eye(4)
        c2w[:3, :3] = R @ c.rotation
        c2w[:3, 3] = s * R @ c.center + t
        out[k] = c.with_pose(c2w)
    return out


def test_known_similarity_is_recovered_exactly():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(30, 3))
    R = _random_rotation(rng)
    s, t = 2.7, np.array([1.0, -3.0, 0.5])
    s2, R2, t2 = similarity_align(src, apply_similarity(s, R, t, src))
    assert s2 == pytest.approx(s, abs=1e-12)
    np.testing.assert_allclose(R2, R, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)


def test_no_reflection_even_for_mirrored_points():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(20, 3))
    _, R, _ = similarity_align(src, src * np.array([1.0, 1.0, -1.0]))
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_noise_gives_small_errors_that_grow_with_the_noise():
    rng = np.random.default_rng(2)
    src = rng.uniform(-1, 1, size=(200, 3))
    R = _random_rotation(rng)
    dst = apply_similarity(0.5, R, np.zeros(3), src)
    errs = []
    for sigma in (1e-4, 1e-2):
        s2, R2, _ = similarity_align(src, dst + rng.normal(scale=sigma, size=dst.shape))
        errs.append(rotation_angle_deg(R2.T @ R))
        assert abs(s2 - 0.5) < 20 * sigma
    assert errs[0] < 0.01 and errs[1] < 1.0 and errs[0] < errs[1]


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError):
        similarity_align(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError):
        similarity_align(np.zeros((5, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError):
        similarity_align(np.ones((5, 3)), np.zeros((5, 3)))


def test_scene_size_is_the_largest_centre_distance():
    pts = np.array([[0, 0, 0], [3, 0, 0], [0, 4, 0.0]])
    assert scene_size(pts) == pytest.approx(5.0)


def _orbit(n: int = 12) -> dict[str, Camera]:
    cams = orbit_cameras(n, 20.0, 3.0, 64, 48, 50.0)
    return {f"{i + 1:04d}": c for i, c in enumerate(cams)}


@pytest.mark.parametrize("align", ["poses", "centers"])
def test_pose_errors_zero_for_a_similar_copy(align):
    ref = _orbit()
    rng = np.random.default_rng(3)
    est = _transform_cameras(ref, 0.3, _random_rotation(rng), np.array([5.0, 1.0, -2.0]))
    est = {k: c.scaled(2.0) for k, c in est.items()}  # other resolution, same field of view
    e = pose_errors(est, ref, align=align)
    assert e["num_frames"] == 12
    assert e["rotation_deg_max"] < 1e-6
    assert e["center_error_max"] < 1e-9
    assert e["focal_ratio"] == pytest.approx(1.0)
    assert e["scale"] == pytest.approx(1 / 0.3)
    assert e["scene_size"] == pytest.approx(6.0 * math.cos(math.radians(20)), rel=1e-6)


def test_pose_errors_measure_perturbations():
    ref = _orbit()
    est = dict(ref)
    # Turn one camera by 2 degrees about its optical axis and move another by 1 % of the scene.
    c = ref["0003"]
    a = math.radians(2.0)
    Rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    m = c.c2w.copy()
    m[:3, :3] = c.rotation @ Rz
    est["0003"] = c.with_pose(m)
    size = scene_size(np.stack([x.center for x in ref.values()]))
    m = ref["0007"].c2w.copy()
    m[:3, 3] += np.array([0, 0, 0.01 * size])
    est["0007"] = ref["0007"].with_pose(m)
    e = pose_errors(est, ref, align="centers")
    # The moved centre tilts the least-squares alignment a little (~0.15 degrees) for everyone.
    assert e["rotation_deg"]["0003"] == pytest.approx(2.0, abs=0.25)
    assert e["rotation_deg_median"] < 0.25
    # ...and absorbs part of the shift, so the moved camera shows somewhat less than its 1 %.
    assert 0.005 < e["center_error"]["0007"] <= 0.0101
    assert e["center_error_median"] < 0.003


def test_pose_alignment_pins_the_rotation_about_a_collinear_track():
    # Centres on a line leave the rotation about it free: only the poses pin it.
    ref = {}
    for i in range(6):
        c2w = np.eye(4)
        c2w[:3, 3] = [i * 0.2, 0.0, 0.0]
        ref[f"{i:04d}"] = Camera(64, 64, 60, 60, 32, 32, c2w)
    rng = np.random.default_rng(4)
    R = _random_rotation(rng)
    est = _transform_cameras(ref, 2.0, R, np.zeros(3))
    est = {k: c.with_pose(c.c2w + np.pad(rng.normal(scale=1e-4, size=(3, 1)), ((0, 1), (3, 0)))) for k, c in est.items()}
    assert pose_errors(est, ref, align="poses")["rotation_deg_max"] < 0.05


def test_too_few_shared_frames():
    ref = _orbit(4)
    with pytest.raises(ValueError, match="at least 3"):
        pose_errors({k: ref[k] for k in list(ref)[:2]}, ref)
