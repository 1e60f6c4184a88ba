"""The refinement on small scenes: views of an analytic field rendered by the shared volume renderer,
fitted from scratch or from a decoded field. The fit must lower its loss, keep the best state when
cancelled, stay inside the masks' hull, and round-trip through the refined-state file."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.cameras import orbit_cameras
from lirm.engine.errors import LirmUserError
from lirm.engine.model.analytic_fields import SphereField
from lirm.engine.model.config import preset
from lirm.engine.model.field_state import load_field, load_field_state, save_field_state
from lirm.engine.model.lirm import LIRM
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import APPEARANCE_WEIGHT, RefineConfig, refine_preset
from lirm.engine.refine.ray_rendering import render_ray_batch
from lirm.engine.refine.refinable_field import RefinableField
from lirm.engine.refine.refine_views import RefineViews
from lirm.engine.refine.refiner import refine_field

SMALL = RefineConfig(minutes=None, iterations=40, rays_per_step=384, coarse_samples=24, fine_samples=8,
                     plane_resolutions=(16, 32), eikonal_points=128, best_every=5, hull_resolution=32)


@pytest.fixture(scope="module")
def sphere_views(analytic_views) -> RefineViews:
    """6 views of a checkered sphere of radius 0.5, 32 px."""
    return analytic_views(SphereField(sphere_radius=0.5), orbit_cameras(6, 20.0, 2.6, 32, 32, 50.0))


def _tiny_field(seed: int = 0) -> RefinableField:
    return initial_fields.scratch(preset("tiny"), 16, seed)


def test_views_flatten_every_pixel_with_its_ray_and_list_the_edges(sphere_views):
    v = sphere_views
    assert v.pixels == 6 * 32 * 32 and v.origins.shape == (v.pixels, 3)
    assert torch.allclose(v.directions.norm(dim=-1), torch.ones(v.pixels), atol=1e-5)
    edges = v.alphas[v.edge_index]
    assert 0 < len(v.edge_index) < v.pixels / 2 and edges.min() < 0.5 < edges.max()
    batch = v.sample_rays(100, 0.25, torch.Generator().manual_seed(0))
    assert batch.shape == (100,) and int(batch.max()) < v.pixels
    with pytest.raises(LirmUserError, match="NaN"):
        RefineViews.build(["a"], v.cameras[:1], np.full((1, 32, 32, 3), np.nan), v.masks[:1])


def test_hull_grid_holds_the_object_and_samples_stay_in_it(sphere_views):
    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, dilation_voxels=1)
    centre = grid.lookup(torch.zeros(1, 3))
    corner = grid.lookup(torch.tensor([[0.9, 0.9, 0.9]]))
    assert bool(centre) and not bool(corner)
    assert 0.05 < grid.occupied_fraction < 0.4  # a ball of radius 0.5 fills 6.5% of the cube; the hull a bit more
    field = _tiny_field().field()
    index = torch.arange(0, sphere_views.pixels, 37)
    out = render_ray_batch(field, sphere_views.origins[index], sphere_views.directions[index], grid, 0.05, 16, 8)
    assert out.colour.shape == (len(index), 3) and torch.isfinite(out.colour).all()
    assert 0 < out.samples < len(index) * 24  # empty space was skipped


def test_batches_can_be_drawn_only_from_rays_that_meet_the_hull(sphere_views):
    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, dilation_voxels=1)
    through = sphere_views.through_grid(grid, 1.0)
    chosen = through.uniform_index
    assert chosen is not None and 0 < len(chosen) < sphere_views.pixels
    # Every object pixel's ray meets the hull; the chosen ones are those that render non-empty. A ray
    # left out renders (nearly) empty whatever the field: the render's jittered samples may graze a
    # voxel corner that the check's fixed steps passed by (seen: 1e-5 of opacity), nothing more.
    assert bool(torch.isin((sphere_views.alphas > 0.5).nonzero(as_tuple=True)[0], chosen).all())
    field = _tiny_field().field()
    with torch.no_grad():  # only the opacities are looked at
        out = render_ray_batch(field, sphere_views.origins, sphere_views.directions, grid, 0.05, 48, 8,
                               generator=torch.Generator().manual_seed(0))
    missed = torch.ones(sphere_views.pixels, dtype=torch.bool)
    missed[chosen] = False
    assert float(out.opacity[missed].abs().max()) < 1e-3 and float(out.opacity[chosen].max()) > 0.1
    batch = through.sample_rays(400, 0.25, torch.Generator().manual_seed(0))
    uniform = batch[:300]  # the edge share comes after the uniform one
    assert bool(torch.isin(uniform, chosen).all())
    assert sphere_views.uniform_index is None  # the original views are unchanged
    result = refine_field(_tiny_field(), sphere_views, replace(SMALL, iterations=6, rays_through_hull=True), grid)
    assert result.steps == 6 and all(np.isfinite(h["loss"]) for h in result.history)


def test_appearance_heads_read_only_the_samples_with_weight_and_the_render_barely_moves(sphere_views):
    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, 1)
    refinable = _tiny_field()
    index = torch.arange(0, sphere_views.pixels, 7)
    origins, directions = sphere_views.origins[index], sphere_views.directions[index]

    def render(prune_weight):
        field = refinable.field()
        read = []
        plain = field.sample_features
        field.sample_features = lambda f, *args, **kwargs: read.append(f.shape[1]) or plain(f, *args, **kwargs)
        out = render_ray_batch(field, origins, directions, grid, 0.01, 32, 16, torch.Generator().manual_seed(3),
                               prune_weight=prune_weight)
        gradient, = torch.autograd.grad(out.colour.sum() + out.albedo.sum(), refinable.planes)
        return out, read, gradient

    pruned, read, pruned_gradient = render(APPEARANCE_WEIGHT)
    full, read_all, full_gradient = render(0.0)
    assert read_all == [full.samples] and read[0] < 0.7 * pruned.samples  # behind the surface nothing is read
    assert torch.equal(pruned.opacity, full.opacity)
    assert (pruned.colour - full.colour).abs().max() < 5e-3 and (pruned.albedo - full.albedo).abs().max() < 5e-3
    cosine = torch.nn.functional.cosine_similarity(pruned_gradient.flatten(), full_gradient.flatten(), dim=0)
    assert cosine > 0.99, cosine


def test_refinement_lowers_its_loss_and_learns_the_silhouette(sphere_views):
    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, 1)
    result = refine_field(_tiny_field(), sphere_views, SMALL, grid)
    assert result.steps == SMALL.iterations and result.stopped == "iterations"
    first, last = result.history[0]["loss"], result.history[-1]["loss"]
    assert last < 0.7 * first, (first, last)
    # The fitted field's SDF: inside at the centre, outside near the bounding sphere's edge.
    field = result.field.frozen_field()
    sdf = field.sdf(torch.tensor([[[0.0, 0.0, 0.0], [0.0, 0.0, 0.9]]]))[0]
    assert sdf[0] < 0 < sdf[1]
    # It carries the beta of the state kept (the schedule's end, reached by then), for the export's surface level.
    assert field.fitted_beta == pytest.approx(1.0 / SMALL.inv_beta[1]), field.fitted_beta


def test_a_predicted_material_is_kept_where_the_photos_say_nothing(sphere_views):
    """A plain fit (radiance only) cannot see roughness or metallic: the prior's prediction it started
    from is kept (start_has_materials), where a start that knows nothing is pulled to 0.5 and 0."""
    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, 1)
    surface = 0.5 * torch.nn.functional.normalize(torch.randn(1, 256, 3, generator=torch.Generator().manual_seed(0)), dim=-1)
    config = replace(SMALL, head_lr=3e-2, losses=replace(SMALL.losses, material_prior=1.0))
    roughness = {}
    for anchored in (True, False):
        start = _tiny_field(seed=4)
        with torch.no_grad():  # a prediction of glossy metal everywhere
            start.heads.roughness[-1].bias.fill_(-2.0)
            start.heads.metallic[-1].bias.fill_(2.0)
        result = refine_field(start, sphere_views, config, grid, start_has_materials=anchored)
        sample = result.field.frozen_field().sample(surface)
        roughness[anchored] = (float(sample.roughness.mean()), float(sample.metallic.mean()))
    assert roughness[True][0] < 0.2 and roughness[True][1] > 0.8, roughness
    assert roughness[False][0] > roughness[True][0] + 0.1 and roughness[False][1] < roughness[True][1] - 0.2, roughness


def _refined_with_terms(sphere_views, inverse_rendering: bool = True, material_net: str = "", material_network: str = "off",
                        footprint_roughness: bool = False, **weights):
    """Ten steps from the tiny field on the sphere's views with the given loss weights; with
    `inverse_rendering`, the materials fitted from the first step under an 8 x 16 studio panorama.
    Returns (the result, the lighting or None)."""
    from lirm.engine.lighting.panorama_lighting import PanoramaLighting
    from lirm.renderer.procedural_environments import make_procedural_environment

    hull = initial_fields.masks_hull(sphere_views, 32, 1.0)
    grid = initial_fields.sampling_grid(hull, 1.0, 1)
    lighting = None
    config = replace(SMALL, iterations=10, losses=replace(SMALL.losses, **weights), material_net=material_net,
                     material_network=material_network, footprint_roughness=footprint_roughness)
    if inverse_rendering:
        lighting = PanoramaLighting.from_environment(make_procedural_environment("studio", width=64), height=8)
        config = replace(config, inverse_rendering=True, pbr_start=0.0)
    return refine_field(_tiny_field(), sphere_views, config, grid, lighting=lighting), lighting


def _term_values(result, name: str) -> list[float]:
    return [h[name] for h in result.history if name in h]


def test_the_inverse_rendering_fits_with_the_albedo_pairs_in_every_batch(sphere_views):
    """With the pair term on, a share of each batch comes as neighbours and the term is in the loss."""
    result, lighting = _refined_with_terms(sphere_views, albedo_pairs=1.0)
    paired = _term_values(result, "albedo_pairs")
    assert paired and all(np.isfinite(v) and v > 0 for v in paired), result.history
    assert result.lighting is lighting and torch.isfinite(lighting.log_radiance).all()


def test_the_inverse_rendering_shares_materials_between_like_albedos(sphere_views):
    """With the shared-materials term on, it is in the loss of every step of the inverse rendering."""
    result, _ = _refined_with_terms(sphere_views, shared_materials=1.0, share_metallic=False)
    shared = _term_values(result, "shared_materials")
    assert shared and all(np.isfinite(v) and v >= 0 for v in shared), result.history


def test_the_inverse_rendering_keeps_the_albedo_from_following_the_normal(sphere_views):
    """With the unshaded-albedo term on, it is in the loss of every step of the inverse rendering."""
    result, _ = _refined_with_terms(sphere_views, albedo_unshaded=1.0)
    unshaded = _term_values(result, "albedo_unshaded")
    assert unshaded and all(np.isfinite(v) and v >= 0 for v in unshaded), result.history


def test_the_pixel_footprint_widens_the_lobe_the_inverse_rendering_shades(sphere_views):
    """With footprint_roughness the PBR term shades each ray with its pixel's spread of normals added:
    the same steps from the same seed give other (finite) photometric errors."""
    plain, _ = _refined_with_terms(sphere_views)
    widened, _ = _refined_with_terms(sphere_views, footprint_roughness=True)
    before, after = _term_values(plain, "pbr"), _term_values(widened, "pbr")
    assert len(before) == len(after) and all(np.isfinite(v) for v in after)
    assert before[0] != after[0]


def test_the_inverse_rendering_holds_the_materials_to_the_material_networks(sphere_views, tmp_path):
    """With the image-space material terms on, each is in the loss of every step of the inverse rendering."""
    from lirm.engine.model.material_net import PRESETS, MaterialNet, save_material_net

    torch.manual_seed(0)
    path = save_material_net(MaterialNet(PRESETS["small"]), tmp_path / "materials.safetensors")
    result, _ = _refined_with_terms(sphere_views, material_net=str(path), material_network="on", image_metallic=1.0,
                                    image_roughness=1.0, image_albedo=1.0, image_albedo_shade=1.0, image_roughness_unseen=1.0)
    for name in ("image_metallic", "image_roughness", "image_albedo", "image_albedo_shade", "image_roughness_unseen"):
        values = _term_values(result, name)
        assert values and all(np.isfinite(v) and v > 0 for v in values), result.history
    assert "as asked" in result.material_network


def test_by_default_the_material_network_is_heard_only_on_photos_it_knows(sphere_views):
    """'auto' asks the network's familiarity check first: the terms are in the loss exactly when it passes."""
    from lirm.engine.model.material_net import load_material_net
    from lirm.engine.model.material_net_familiarity import material_net_familiarity
    from lirm.engine.refine.image_materials import shipped_material_net

    assert SMALL.material_network == "auto" and SMALL.losses.image_metallic > 0 and SMALL.losses.image_albedo > 0
    result, _ = _refined_with_terms(sphere_views, material_network="auto")
    familiarity = material_net_familiarity(load_material_net(shipped_material_net())[0], sphere_views.images, sphere_views.masks)
    assert result.material_network == familiarity.describe()
    assert bool(_term_values(result, "image_metallic")) == familiarity.familiar
    off, _ = _refined_with_terms(sphere_views, material_network="off")
    assert off.material_network == "" and not _term_values(off, "image_metallic")


def test_the_albedo_smoothness_term_is_in_the_loss(sphere_views):
    result, _ = _refined_with_terms(sphere_views, inverse_rendering=False, albedo_smooth=1.0)
    smooth = _term_values(result, "albedo_smooth")
    assert smooth and all(np.isfinite(v) and v >= 0 for v in smooth), result.history


def test_sdf_shading_normals_are_the_surface_normals_and_carry_gradients(sphere_views):
    from lirm.engine.refine.ray_rendering import with_sdf_normals

    class Sphere(SphereField):
        def sample(self, points, view_dirs=None, materials=True):
            return super().sample(points, view_dirs)

    sphere = Sphere(sphere_radius=0.5)
    index = torch.arange(0, sphere_views.pixels, 7)
    origins, directions = sphere_views.origins[index], sphere_views.directions[index]
    render = render_ray_batch(sphere, origins, directions, None, 0.01, 48, 16)
    shaded = with_sdf_normals(sphere, render, origins, directions)
    hit = render.opacity > 0.5
    assert hit.sum() > 50
    points = origins[hit] + (render.depth[hit] / render.opacity[hit])[:, None] * directions[hit]
    cosine = torch.nn.functional.cosine_similarity(shaded.normal[hit], points, dim=-1)
    assert cosine.min() > 0.99, cosine.min()
    torch.testing.assert_close(shaded.normal[~hit], render.normal[~hit])
    # On a trainable field the normals differentiate into the planes and the SDF head, not the normal head.
    refinable = _tiny_field()
    field = refinable.field()
    render = render_ray_batch(field, origins, directions, None, 0.05, 24, 8)
    render = replace(render, opacity=torch.ones_like(render.opacity), depth=torch.full_like(render.depth, 2.6))
    with_sdf_normals(field, render, origins, directions).normal.sum().backward()
    assert refinable.planes.grad is not None and float(refinable.planes.grad.abs().sum()) > 0
    assert all(p.grad is None or float(p.grad.abs().sum()) == 0 for p in refinable.heads.normal.parameters())
    assert any(p.grad is not None and float(p.grad.abs().sum()) > 0 for p in refinable.heads.sdf.parameters())
    # Held fixed ("sdf-fixed"): the same normals, and nothing reaches the field through them.
    render = render_ray_batch(field, origins, directions, None, 0.05, 24, 8)
    render = replace(render, opacity=torch.ones_like(render.opacity), depth=torch.full_like(render.depth, 2.6))
    fixed = with_sdf_normals(field, render, origins, directions, shape_surface=False)
    torch.testing.assert_close(fixed.normal.detach(), with_sdf_normals(field, render, origins, directions).normal.detach())
    for parameter in [refinable.planes, *refinable.heads.parameters()]:
        parameter.grad = None
    fixed.normal.sum().backward()
    assert all(p.grad is None or float(p.grad.abs().sum()) == 0 for p in refinable.heads.sdf.parameters())
    assert refinable.planes.grad is None or float(refinable.planes.grad.abs().sum()) == 0


def test_cancel_keeps_the_state_reached(sphere_views):
    calls = []
    cancel_after = 12

    def cancel() -> bool:
        calls.append(1)
        return len(calls) > cancel_after

    start = _tiny_field(seed=3)
    before = start.snapshot()
    result = refine_field(start, sphere_views, SMALL, None, cancel=cancel)
    assert result.stopped == "cancelled" and result.steps == cancel_after
    assert not torch.equal(result.field.planes.detach(), before["planes"])  # the work done is kept, not thrown away


def test_keyboard_interrupt_stops_the_loop_and_keeps_the_best(sphere_views):
    ticks = []

    def progress(tick) -> None:
        ticks.append(tick)
        if tick.step == 30:
            raise KeyboardInterrupt

    result = refine_field(_tiny_field(), sphere_views, SMALL, None, progress=progress)
    assert result.stopped == "cancelled" and result.steps == 30
    assert 1 <= result.best_step <= 30 and np.isfinite(result.best_loss)
    assert ticks[-1].resolution == 32 and 0 < ticks[-1].fraction <= 1 and ticks[-1].eta >= 0


def test_decoded_field_resamples_to_finer_planes_without_moving_the_surface():
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).eval()
    with torch.no_grad():
        field = model.decode(model.initial_state(1))
    refinable = initial_fields.from_lirm(field, 64)
    assert refinable.resolution == 64 and field.planes.shape[-1] == 32
    points = torch.rand(1, 500, 3) * 1.6 - 0.8
    with torch.no_grad():
        before, after = field.sdf(points), refinable.field().sdf(points)
    assert torch.allclose(before, after, atol=0.05)
    assert refinable.field().normal_eps == pytest.approx(0.5 * field.normal_eps)
    assert next(model.heads.parameters()) is not next(refinable.heads.parameters())  # the model is never changed


def test_refined_state_round_trips_and_refuses_garbage(tmp_path):
    field = _tiny_field(seed=5).frozen_field()
    assert load_field_state(save_field_state(field, tmp_path / "old.safetensors", updates=1))[0].fitted_beta is None
    field.fitted_beta = 0.002
    path = save_field_state(field, tmp_path / "state.safetensors", updates=3, extra={"started_from": "scratch"})
    loaded, extra = load_field_state(path)
    assert extra == {"started_from": "scratch", "updates": 3} and loaded.fitted_beta == 0.002
    points = torch.rand(1, 200, 3) * 2 - 1
    dirs = torch.nn.functional.normalize(torch.randn(1, 200, 3), dim=-1)
    a, b = field.sample(points, dirs), loaded.sample(points, dirs)
    assert torch.allclose(a.sdf, b.sdf) and torch.allclose(a.colour, b.colour) and torch.allclose(a.albedo, b.albedo)
    assert torch.allclose(load_field(path).sdf(points), a.sdf)  # load_field needs no model for a refined state
    (tmp_path / "bad.safetensors").write_bytes(b"not a state")
    with pytest.raises(LirmUserError, match="corrupt or truncated"):
        load_field(tmp_path / "bad.safetensors")
    nan_field = type(field)(field.config, field.heads, field.planes * float("nan"), field.panoramas)
    with pytest.raises(LirmUserError, match="NaN"):
        save_field_state(nan_field, tmp_path / "nan.safetensors", 1)
    assert not (tmp_path / "nan.safetensors").exists()


def test_presets_and_bad_settings():
    assert refine_preset("fast").minutes == 1.0 and refine_preset("default").minutes == 3.0
    with pytest.raises(ValueError, match="unknown refinement preset"):
        refine_preset("slow")
    with pytest.raises(ValueError, match="positive"):
        RefineConfig(minutes=0)
    with pytest.raises(ValueError, match="plane resolutions"):
        RefineConfig(plane_resolutions=(4,))
    with pytest.raises(ValueError, match="shading normal"):
        RefineConfig(shading_normal="mesh")


def test_bench_options_set_one_setting_each_and_refuse_unknown_ones():
    from lirm.engine.bench.refine_bench import apply_options

    config = apply_options(refine_preset("default"), ["losses.eikonal=0", "edge_ray_fraction=0", "plane_resolutions=192"])
    assert config.losses.eikonal == 0 and config.edge_ray_fraction == 0 and config.plane_resolutions == (192,)
    assert config.losses.colour == refine_preset("default").losses.colour
    for bad in ("losses.nope=1", "nope=1", "edge_ray_fraction", "minutes=abc"):
        with pytest.raises(LirmUserError):
            apply_options(refine_preset("default"), [bad])


def test_bench_options_take_text_settings_as_written():
    """A path or a choice needs no Python quoting (`--option material_net=/path/net.safetensors` once
    failed as "not a number"); a choice the config refuses names the option."""
    from lirm.engine.bench.refine_bench import apply_options

    config = apply_options(refine_preset("default"), ["material_net=/tmp/other net.safetensors", "material_network='off'",
                                                      "shading_normal=head"])
    assert config.material_net == "/tmp/other net.safetensors" and config.material_network == "off"
    assert config.shading_normal == "head"
    with pytest.raises(LirmUserError, match="material_network=sometimes"):
        apply_options(refine_preset("default"), ["material_network=sometimes"])


def test_the_outside_bounds_term_is_in_the_loss_and_read_with_the_eikonals_probes(sphere_views):
    """The term keeping the field empty outside the sampling grid is in every step's loss, and its
    value read in one pass with the eikonal's probes (the mean of six central-difference probes) is
    within 2% of what a read of its own gives."""
    from lirm.engine.refine.config import LossWeights
    from lirm.engine.refine.objective import batch_loss
    from lirm.engine.refine.outside_bounds import OutsideBounds

    result, _ = _refined_with_terms(sphere_views, inverse_rendering=False, outside_bounds=1.0)
    values = _term_values(result, "outside_bounds")
    assert len(values) == len(result.history) and all(np.isfinite(v) and v >= 0 for v in values), result.history
    field = _tiny_field().field()
    index = torch.arange(0, sphere_views.pixels, 7)
    render = render_ray_batch(field, sphere_views.origins[index], sphere_views.directions[index], None, 0.05, 24, 8)
    grid = initial_fields.sampling_grid(initial_fields.masks_hull(sphere_views, 32, 1.0), 1.0, 1)
    points = OutsideBounds(grid).points(256, torch.Generator().manual_seed(0), torch.device("cpu"))
    points[:, 3] += 1.0  # bounds no point meets, so that the hinge reads every point
    _, terms = batch_loss(field, render, sphere_views.colours[index], sphere_views.alphas[index],
                          LossWeights(outside_bounds=1.0), 64, torch.Generator().manual_seed(0), outside_points=points)
    assert "eikonal" in terms  # the shared read, not the fallback
    # Within the six probes' second-order error (their half step is half the field's normal step).
    assert terms["outside_bounds"] == pytest.approx(float(OutsideBounds.loss(field, points).detach()), rel=0.02)
