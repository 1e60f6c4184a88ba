"""The opening continued down where no photo saw: a deep cup's inside hollowed to its floor, its walls
and floor kept; a tray whose floor the photos see and a solid keep what they have. Photos sphere-traced
from exact signed distances (conftest.SphereTracedCup), so every voxel is checked against the truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from lirm.engine.evaluation.carved_hull import HullField
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig
from lirm.engine.refine.photo_carving import PhotoCarving, photo_carve_occupancy
from lirm.engine.refine.refine_views import RefineViews
from lirm.engine.refine.unseen_hollow import UnseenHollowConfig, hollow_below_opening

RADIUS, RESOLUTION = 1.0, 48  # the cup's (conftest.SphereTracedCup)
VOXEL = 2.0 * RADIUS / RESOLUTION


def carved(cup, hollow: bool = True, views: int = 12):
    cameras, images, masks = cup.shoot(hollow=hollow, textured=True, views=views)
    hull = cup.hull_of(cameras, images, masks)
    return cameras, images, masks, hull, photo_carve_occupancy(hull, RADIUS, cameras, images, masks)


@pytest.fixture(scope="module")
def deep_cup(sphere_traced_cup):
    # A floor 0.1 thick (2.4 voxels, 8% of its height): the prior keeps the walls' thickness or 6% of
    # the height over the base, so a floor thicker than that (the fixture's default 0.2) loses its top.
    cup = sphere_traced_cup(depth=1.1)
    return (cup, *carved(cup))


def true_inside(cup, hull: np.ndarray, margin_voxels: float) -> np.ndarray:
    """Indices of the hull's voxels inside the cup's opening, this far from its walls and floor."""
    index = np.argwhere(hull)
    centres = cup.voxel_centres(index)
    inside = ((cup.sdf(centres) > margin_voxels * VOXEL) & (centres[:, 2] < 0.6) & (centres[:, 2] > 0.6 - cup.depth)
              & (np.linalg.norm(centres[:, :2], axis=1) < 0.47))
    return index[inside]


def test_a_deep_cup_is_hollowed_to_its_floor_and_keeps_its_walls(deep_cup):
    cup, *_, hull, carving = deep_cup
    hollow = hollow_below_opening(hull, carving)
    # (The hollow keeps a voxel more wall than the hull's walls measure: farther than 2 voxels from the
    # true walls and floor, the inside all goes.)
    inside = tuple(true_inside(cup, hull, 2.0).T)
    # The photos, from 40 degrees, carve the opening's upper part only; the prior takes the rest.
    assert carving.occupancy[inside].mean() > 0.5
    assert hollow.occupancy[inside].mean() < 0.01
    gone = np.argwhere(carving.occupancy & ~hollow.occupancy)
    assert hollow.hollowed_voxels == len(gone) > 1000
    # Nothing of the walls or the floor goes: every hollowed voxel's centre lies outside the solid.
    assert np.all(cup.sdf(cup.voxel_centres(gone)) > 0.0)
    assert 1.5 <= hollow.wall_voxels <= 4.0  # the walls the photos saw: 0.08 thick, 1.9 voxels (the hull a voxel fatter)
    assert not hollow.why_not and "continued down" in hollow.sentence()
    # Only ever removes.
    assert not np.any(hollow.occupancy & ~carving.occupancy)


def test_the_hollow_spans_the_opening_where_the_carving_left_patches(deep_cup):
    """Photos that matched the opening in patches (plain glaze between, or spots no two views saw)
    still hollow all of it below: the inside goes across the opening's outline, not only down the
    carved columns (under the patches those stood as walls and pillars: the synthetic mug's inside was
    59% hollowed, 73% now, the rest its floor)."""
    cup, *_, hull, carving = deep_cup
    removed = hull & ~carving.occupancy
    stripes = (np.arange(hull.shape[0]) % 8 < 4)[:, None, None]  # every other band of 4 voxels across x
    patchy = PhotoCarving(carving.occupancy | (removed & stripes), carving.carved_voxels, carving.hull_voxels,
                          carving.pixels_seeing_through, seen_surface=carving.seen_surface)
    hollow = hollow_below_opening(hull, patchy)
    index = true_inside(cup, hull, 2.0)
    under_stripes = index[stripes[index[:, 0], 0, 0] & (cup.voxel_centres(index)[:, 2] < 0.0)]
    assert len(under_stripes) > 100 and hollow.occupancy[tuple(under_stripes.T)].mean() < 0.05
    gone = np.argwhere(patchy.occupancy & ~hollow.occupancy)
    assert np.all(cup.sdf(cup.voxel_centres(gone)) > 0.0)  # still none of the walls or the floor


def test_the_lid_the_hull_keeps_over_the_opening_goes(deep_cup):
    """The sweep carves nothing within two voxels of the hull's surface, so the masks' hull can keep a
    lid over the opening (the synthetic mugs'): the photos look through it, and it goes too, all but
    the rim round it; a surface the photos matched stops it."""
    cup, *_, hull, carving = deep_cup
    removed = hull & ~carving.occupancy
    layers = np.nonzero(removed.any(axis=(0, 1)))[0]
    lid = removed & (np.arange(hull.shape[2]) >= layers.max() - 1)[None, None, :]  # its top two layers kept
    capped = PhotoCarving(carving.occupancy | lid, carving.carved_voxels, carving.hull_voxels,
                          carving.pixels_seeing_through, seen_surface=carving.seen_surface)
    hollow = hollow_below_opening(hull, capped)
    in_lid = np.argwhere(lid)
    centres = cup.voxel_centres(in_lid)
    in_lid = in_lid[(cup.sdf(centres) > 2.0 * VOXEL) & (np.linalg.norm(centres[:, :2], axis=1) < 0.47 - 2.0 * VOXEL)]
    assert len(in_lid) > 20 and hollow.occupancy[tuple(in_lid.T)].mean() < 0.05
    gone = np.argwhere(capped.occupancy & ~hollow.occupancy)
    assert np.all(cup.sdf(cup.voxel_centres(gone)) > 0.0)  # the rim stays
    # A lid the photos matched (a real one) stays.
    matched = PhotoCarving(capped.occupancy, 0, 0, 0, seen_surface=carving.seen_surface | lid)
    assert hollow_below_opening(hull, matched).occupancy[tuple(in_lid.T)].all()


def test_a_tray_whose_floor_the_photos_see_is_left_as_carved(sphere_traced_cup):
    cup = sphere_traced_cup(depth=0.25)
    *_, hull, carving = carved(cup)
    hollow = hollow_below_opening(hull, carving)
    assert hollow.hollowed_voxels == 0 and np.array_equal(hollow.occupancy, carving.occupancy)
    assert hollow.seen_bottom_share > UnseenHollowConfig().max_seen_share
    assert "saw its bottom" in hollow.sentence()


def test_a_solid_is_not_hollowed(sphere_traced_cup):
    cup = sphere_traced_cup()
    *_, hull, carving = carved(cup, hollow=False, views=10)
    hollow = hollow_below_opening(hull, carving)
    assert hollow.hollowed_voxels == 0 and np.array_equal(hollow.occupancy, carving.occupancy)


def test_the_up_axis_is_the_configs(deep_cup):
    """The same hull with its up along x gives the same hollow along x."""
    *_, hull, carving = deep_cup
    upright = hollow_below_opening(hull, carving)
    turn = lambda a: None if a is None else np.moveaxis(a, 2, 0)  # noqa: E731
    lying = PhotoCarving(turn(carving.occupancy), carving.carved_voxels, carving.hull_voxels,
                         carving.pixels_seeing_through, seen_surface=turn(carving.seen_surface))
    turned = hollow_below_opening(turn(hull), lying, UnseenHollowConfig(up_axis=0))
    assert np.array_equal(turned.occupancy, turn(upright.occupancy))


def test_nothing_carved_or_nothing_recorded_says_why(deep_cup):
    *_, hull, carving = deep_cup
    untouched = PhotoCarving(hull, 0, int(hull.sum()), 0, seen_surface=np.zeros_like(hull))
    assert "removed nothing" in hollow_below_opening(hull, untouched).sentence()
    with pytest.raises(ValueError, match="seen_surface"):
        hollow_below_opening(hull, PhotoCarving(carving.occupancy, carving.carved_voxels, carving.hull_voxels, 0))


def test_the_refinement_starts_from_the_hollowed_hulls(deep_cup):
    """`views_hulls` with the carving on: both hulls lose the hollow too, and the notes say so."""
    cup, cameras, images, masks, hull, _ = deep_cup
    views = RefineViews.build([f"v{i}" for i in range(len(cameras))], cameras, images, masks)
    config = replace(RefineConfig(), hull_resolution=RESOLUTION, photo_carving=True)
    assert config.hollow_openings  # on with the carving by default
    only_carved = initial_fields.views_hulls(views, replace(config, hollow_openings=False), RADIUS)
    hulls = initial_fields.views_hulls(views, config, RADIUS)
    # Carved and hollowed from the footprint hull: a voxel fatter, so are the walls and the floor it
    # keeps. The start keeps a voxel more of wall (below).
    def inside(margin_voxels: float) -> tuple:
        index = true_inside(cup, hull, margin_voxels)
        return tuple(index[cup.voxel_centres(index)[:, 2] > -0.2].T)

    assert only_carved.centres.occupancy[inside(2.0)].mean() > 0.5
    assert hulls.footprint.occupancy[inside(2.0)].mean() < 0.01 and hulls.centres.occupancy[inside(3.0)].mean() < 0.01
    assert hulls.hollow is not None and hulls.hollow.hollowed_voxels > 1000
    # The start keeps walls its signed distance holds (the hollow's core only: with the whole hollow
    # gone from it, the demo mug's walls were a voxel thin, the smoothed SDF positive everywhere, and
    # the refinement started from nothing).
    start = HullField(hulls.centres, RADIUS)
    kept = np.argwhere(hulls.centres.occupancy)
    assert (start.sdf(torch.from_numpy(cup.voxel_centres(kept)).float()[None]) < 0).float().mean() > 0.9
    hollow = hulls.carving.occupancy & ~hulls.hollow.occupancy
    assert np.array_equal(only_carved.footprint.occupancy & ~hulls.footprint.occupancy, hollow)
    assert np.array_equal(only_carved.centres.occupancy & ~hulls.centres.occupancy,
                          only_carved.centres.occupancy & hulls.hollow.core)
    assert not np.any(hulls.hollow.core & ~hollow) and hulls.hollow.core.sum() > 0.5 * hollow.sum()
    assert hulls.sentences() == [hulls.carving.sentence(), hulls.hollow.sentence()]
