"""The fittable low-resolution lighting: its split-sum terms, its observation and smoothness terms."""

from __future__ import annotations

import numpy as np
import torch

from lirm.engine.lighting.capture_lighting import CaptureLighting, CaptureLightingConfig
from lirm.engine.lighting.panorama_lighting import PanoramaLighting
from lirm.engine.lighting.split_sum_shading import shade
from lirm.renderer.environment import Environment
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS, make_procedural_environment


def test_a_uniform_panorama_lights_every_normal_and_lobe_alike():
    lighting = PanoramaLighting.from_environment(Environment(np.full((32, 64, 3), 0.7, np.float32)), height=8)
    normals = torch.nn.functional.normalize(torch.randn(50, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    torch.testing.assert_close(lighting.irradiance_over_pi(normals), torch.full((50, 3), 0.7), rtol=0.02, atol=0.0)
    torch.testing.assert_close(lighting.prefiltered(normals, torch.rand(50)), torch.full((50, 3), 0.7), rtol=1e-4, atol=0.0)
    white = shade(lighting, torch.ones(50, 3), torch.ones(50), torch.zeros(50), normals, normals).radiance
    torch.testing.assert_close(white, torch.full((50, 3), 0.7), rtol=0.03, atol=0.0)  # energy conserved, as the renderer


def test_the_sun_side_is_brighter_and_gradients_reach_the_light():
    lighting = PanoramaLighting.from_environment(make_procedural_environment("sky", width=128), height=16)
    up, down = torch.tensor([[0.0, 0.0, 1.0]]), torch.tensor([[0.0, 0.0, -1.0]])
    assert (lighting.irradiance_over_pi(up) > 2 * lighting.irradiance_over_pi(down)).all()
    out = shade(lighting, torch.full((1, 3), 0.5), torch.tensor([0.4]), torch.tensor([0.0]), up, up).radiance
    out.sum().backward()
    assert lighting.log_radiance.grad is not None and lighting.log_radiance.grad.abs().sum() > 0


def test_what_the_photos_saw_holds_the_panorama_and_clipped_light_is_a_lower_bound():
    environment = make_procedural_environment("studio", width=64)
    observed = np.zeros((32, 64))
    observed[16:] = 3.0  # the lower half seen
    clipped = np.zeros((32, 64))
    clipped[24:, :8] = 1.0  # and a corner of it clipped
    estimate = CaptureLighting(environment, observed, clipped, 4, CaptureLightingConfig(width=64))
    lighting = PanoramaLighting.from_capture_lighting(estimate, height=8)
    assert float(lighting.observation_loss().detach()) < 1e-4  # it starts at what was seen
    with torch.no_grad():
        lighting.log_radiance[4:, :] -= 1.0  # darker than seen everywhere seen: penalised
    darker = float(lighting.observation_loss().detach())
    with torch.no_grad():
        lighting.log_radiance[4:, :] += 2.0  # brighter: penalised too, except where clipped
    brighter = float(lighting.observation_loss().detach())
    assert darker > 0.5 and 0.5 < brighter < darker
    with torch.no_grad():
        lighting.log_radiance[:4] = torch.randn(4, 16, 3)
    assert float(lighting.smoothness_loss().detach()) > 0.1  # unseen, but kept smooth by its own term


def test_below_the_sharpest_lobe_roughness_changes_nothing_and_a_finer_floor_lets_it():
    environment = make_procedural_environment("studio", width=128)
    direction = torch.tensor([[0.3, -0.2, 0.93]])
    for texels, differs in ((1.0, False), (0.25, True)):
        panorama = PanoramaLighting.from_environment(environment, 16, sharpest_lobe_texels=texels)
        with torch.no_grad():
            glaze, satin = (panorama.prefiltered(direction, torch.tensor([r])) for r in (0.1, 0.2))
        assert bool((glaze - satin).abs().max() > 1e-4 * satin.abs().max()) == differs, texels


def test_a_compact_light_keeps_its_energy_and_stays_outside_the_smoothness_term():
    lighting = PanoramaLighting(torch.zeros(16, 32, 3), light_lobes=2)
    assert lighting.light_lobes == 2
    smooth_before = float(lighting.smoothness_loss().detach())
    energies = []
    for sharpness in (2.0, 30.0, 100.0):  # broad to about a texel wide
        with torch.no_grad():
            lighting.lobe_log_sharpness.fill_(np.log(sharpness))
            lighting.lobe_axes.copy_(torch.tensor([[0.31, 0.17, 0.93], [0.9, -0.1, 0.3]]))
        lobes = lighting.lobe_radiance().detach()
        energies.append(float((lobes[:, 0] * lighting.solid_angle).sum()))
        exact = 2 * (2 * np.pi * (1 - np.exp(-2 * sharpness)) / sharpness)  # two lobes of peak 1 (exp(0))
        assert abs(energies[-1] - exact) < 1e-3 * exact
    total = lighting.environment().radiance
    assert total.max() > 1.5 and total.min() >= 1.0 - 1e-6  # the lobes add to the panorama's texels
    assert float(lighting.smoothness_loss().detach()) == smooth_before == 0.0


def test_a_compact_light_fitted_to_the_shading_of_a_sunlit_object_finds_the_sun():
    sky = make_procedural_environment("sky", width=256)
    truth = PanoramaLighting.from_environment(sky, 16)
    normals = torch.nn.functional.normalize(torch.randn(400, 3, generator=torch.Generator().manual_seed(1)), dim=-1)
    with torch.no_grad():
        target = truth.irradiance_over_pi(normals)
        flat = float(truth.radiance.median())
    fit = PanoramaLighting(torch.full((16, 32, 3), np.log(flat)), light_lobes=1)  # a dull sky, a lobe at the zenith
    optimiser = torch.optim.Adam([fit.lobe_axes, fit.lobe_log_amplitude, fit.lobe_log_sharpness], lr=0.05)
    for _ in range(300):
        optimiser.zero_grad()
        (fit.irradiance_over_pi(normals) - target).abs().mean().backward()
        optimiser.step()
    axis = torch.nn.functional.normalize(fit.lobe_axes.detach(), dim=-1)[0].numpy()
    sun = PROCEDURAL_ENVIRONMENTS["sky"].sun_direction
    assert np.degrees(np.arccos(np.clip(axis @ sun, -1, 1))) < 25.0


def test_the_heavy_tailed_smoothness_is_total_variation_for_small_steps_and_lets_a_bright_light_grow():
    sun = torch.zeros(16, 32, 3)
    sun[4, 10] = float(np.log(100.0))  # a sun-like texel, 100 x the sky around it
    plain, heavy = PanoramaLighting(sun), PanoramaLighting(sun, smoothness_scale=0.25)
    x = plain.log_radiance
    total_variation = (x - x.roll(1, dims=1)).abs().mean() + (x[1:] - x[:-1]).abs().mean()
    assert abs(float(plain.smoothness_loss().detach()) - float(total_variation.detach())) < 1e-6  # scale 0: the plain term
    # What brightening the sun further costs: under plain total variation the same at any contrast, so
    # the fit would rather spread the light; under the heavy tail a twentieth of it at this contrast.
    price = []
    for lighting in (plain, heavy):
        lighting.smoothness_loss().backward()
        price.append(float(lighting.log_radiance.grad[4, 10, 0]))
    assert price[1] < 0.06 * price[0] and price[1] > 0
    noise = torch.randn(16, 32, 3, generator=torch.Generator().manual_seed(0)) * 0.01
    faint, faint_plain = PanoramaLighting(noise, smoothness_scale=0.25), PanoramaLighting(noise)
    ratio = float(faint.smoothness_loss().detach()) / float(faint_plain.smoothness_loss().detach())
    assert 0.9 < ratio <= 1.0  # small steps cost what they did: faint unseen texels stay smooth


def test_the_neutrality_term_prices_colour_only_where_no_photo_saw_the_light():
    """A yellow cast on the unseen upper half costs; the same cast on the seen lower half (what the
    photos say) and a grey brightening anywhere do not."""
    environment = Environment(np.full((32, 64, 3), 0.5, np.float32), "grey")
    observed = np.zeros((32, 64))
    observed[16:] = 3.0  # the lower half seen
    estimate = CaptureLighting(environment, observed, np.zeros((32, 64)), 4, CaptureLightingConfig(width=64))
    lighting = PanoramaLighting.from_capture_lighting(estimate, height=8)
    assert float(lighting.neutrality_loss().detach()) < 1e-6
    yellow = torch.tensor([0.5, 0.3, -0.8])
    with torch.no_grad():
        lighting.log_radiance[:] += 1.0  # brighter, still grey
    assert float(lighting.neutrality_loss().detach()) < 1e-6
    with torch.no_grad():
        lighting.log_radiance[4:] += yellow  # the seen half yellow
    assert float(lighting.neutrality_loss().detach()) < 1e-6
    with torch.no_grad():
        lighting.log_radiance[:4] += yellow  # the unseen half yellow
    cost = lighting.neutrality_loss()
    assert abs(float(cost.detach()) - float((yellow - yellow.mean()).abs().mean())) < 1e-5
    cost.backward()
    assert float(lighting.log_radiance.grad[:4].abs().sum()) > 0 and float(lighting.log_radiance.grad[4:].abs().sum()) == 0
