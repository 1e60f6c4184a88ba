"""Training scenes: seeded, the supplementary's camera ranges, auto-exposure, the specular copy."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lirm.engine.synth.training_scenes import TrainingSceneConfig, auto_exposure_ev, make_training_scene, sample_cameras
from lirm.renderer.environment import Environment

SMALL = TrainingSceneConfig(views=4, size=32, supersample=1, environment_width=128)


def test_camera_ranges_follow_the_supplementary():
    _, params = sample_cameras(np.random.default_rng(0), replace(TrainingSceneConfig(), views=2000, size=16))
    fov = np.array([p["fov_deg"] for p in params])
    elevation = np.array([p["elevation_deg"] for p in params])
    azimuth = np.array([p["azimuth_deg"] for p in params])
    assert 15 <= fov.min() < 17 and 83 < fov.max() <= 85
    assert -5 <= elevation.min() < -3 and 68 < elevation.max() <= 70
    assert azimuth.min() < 2 and azimuth.max() > 358


def test_auto_exposure_meters_the_environment():
    bright = Environment(np.full((32, 64, 3), 8.0, np.float32))
    assert auto_exposure_ev(bright) == pytest.approx(-3.0, abs=1e-6)


def test_a_seed_gives_the_same_scene_and_seeds_differ(renderer):
    a = make_training_scene(renderer, 7, SMALL)
    b = make_training_scene(renderer, 7, SMALL)
    c = make_training_scene(renderer, 8, SMALL)
    np.testing.assert_array_equal(a.views.image, b.views.image)
    assert a.description == b.description
    assert a.description.cameras != c.description.cameras
    assert a.views.image.shape == (4, 32, 32, 3) and a.views.albedo.shape == (4, 32, 32, 3)
    assert 0.01 < a.views.mask.mean() < 0.9
    # Every view holds the object (the cameras frame the bounding sphere) and its material maps.
    assert (a.views.mask.reshape(4, -1).max(axis=1) > 0.5).all()


def test_the_specular_copy_scales_roughness_only(renderer):
    plain = make_training_scene(renderer, 3, replace(SMALL, specular_copy_probability=0.0))
    shiny = make_training_scene(renderer, 3, replace(SMALL, specular_copy_probability=1.0))
    assert plain.description.cameras == shiny.description.cameras
    assert plain.description.roughness_scale == 1.0 and 0.3 <= shiny.description.roughness_scale <= 0.6
    inside = plain.views.mask > 0.99
    ratio = shiny.views.roughness[inside].mean() / plain.views.roughness[inside].mean()
    assert ratio == pytest.approx(shiny.description.roughness_scale, rel=0.05)
    np.testing.assert_allclose(plain.views.albedo, shiny.views.albedo, atol=1e-6)


def test_bench_synth_command_writes_a_contact_sheet(tmp_path, capsys):
    import cv2

    from lirm.engine.cli import main

    assert main(["bench", "synth", "--scenes", "2", "--views", "2", "--size", "32", "--sheet", str(tmp_path / "s.png")]) == 0
    assert "views per second" in capsys.readouterr().out
    sheet = cv2.imread(str(tmp_path / "s.png"))
    assert sheet.shape == (2 * 32, 2 * 6 * 32, 3) and sheet.std() > 10
