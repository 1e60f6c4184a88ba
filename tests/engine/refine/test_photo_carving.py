"""The hull carved where the photos see through it: a speckled cup's opening opens, a solid keeps its
inside, and plain surfaces (no evidence) carve nothing. The photos are ray-traced here from an
exact signed distance, so every carved voxel can be checked against the true solid."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig
from lirm.engine.refine.photo_carving import PhotoCarvingConfig, photo_carve_occupancy
from lirm.engine.refine.refine_views import RefineViews

RADIUS, RESOLUTION = 1.0, 48  # the cup's (conftest.SphereTracedCup)


@pytest.fixture(scope="module")
def cup(sphere_traced_cup):
    return sphere_traced_cup()


@pytest.fixture(scope="module")
def speckled_cup(cup):
    cameras, images, masks = cup.shoot(hollow=True, textured=True)
    hull = cup.hull_of(cameras, images, masks)
    return cameras, images, masks, hull, photo_carve_occupancy(hull, RADIUS, cameras, images, masks)


def test_the_masks_hull_caps_the_opening(cup, speckled_cup):
    *_, hull, _ = speckled_cup
    inside_opening = cup.voxel_centres(np.argwhere(hull))
    inside_opening = inside_opening[(np.linalg.norm(inside_opening[:, :2], axis=1) < 0.35) & (inside_opening[:, 2] > 0.3)]
    assert len(inside_opening) > 100  # the lid the carving is for


def test_the_speckled_cups_opening_is_carved_and_its_walls_kept(cup, speckled_cup):
    *_, hull, carving = speckled_cup
    voxel = 2.0 * RADIUS / RESOLUTION
    removed = np.argwhere(hull & ~carving.occupancy)
    assert carving.carved_voxels == len(removed) > 0
    sdf = cup.sdf(cup.voxel_centres(removed))
    # Nothing of the cup's solid goes (a voxel whose centre lies a voxel inside its walls), and every
    # carved voxel is empty or touches the surface.
    assert np.all(sdf > -voxel)
    assert np.mean(sdf > -0.5 * voxel) > 0.97
    # The opening's upper part, which the photos look into, is open: the cavity's voxels within 0.3
    # of the rim (the views from 40 degrees see that deep at its centre).
    centres = cup.voxel_centres(np.argwhere(hull))
    cavity = (cup.sdf(centres) > voxel) & (np.linalg.norm(centres[:, :2], axis=1) < 0.47) & (centres[:, 2] > 0.3)
    kept = carving.occupancy[tuple(np.argwhere(hull)[cavity].T)]
    assert cavity.sum() > 100 and kept.mean() < 0.25, f"{kept.mean():.2f} of the cavity's top still filled"


def test_a_solid_keeps_its_inside(cup):
    cameras, images, masks = cup.shoot(hollow=False, textured=True, views=10)
    hull = cup.hull_of(cameras, images, masks)
    carving = photo_carve_occupancy(hull, RADIUS, cameras, images, masks)
    voxel = 2.0 * RADIUS / RESOLUTION
    removed = cup.voxel_centres(np.argwhere(hull & ~carving.occupancy))
    # Only where the hull stands off the true surface (the cone the 40-degree views leave above its top),
    # never within the solid.
    assert np.all(cup.sdf(removed, hollow=False) > -voxel)
    assert np.mean(cup.sdf(removed, hollow=False) > 0.0) > 0.9  # the hull above the top, which no view saw from above


def test_a_plain_cup_gives_no_evidence_and_keeps_its_lid(cup):
    cameras, images, masks = cup.shoot(hollow=True, textured=False, views=8)
    hull = cup.hull_of(cameras, images, masks)
    carving = photo_carve_occupancy(hull, RADIUS, cameras, images, masks, PhotoCarvingConfig())
    assert carving.carved_voxels == 0 and carving.pixels_seeing_through == 0
    assert np.array_equal(carving.occupancy, hull)


def test_the_refinement_starts_from_the_carved_hulls(speckled_cup):
    """`views_hulls` (what `lirm refine` and the bench start from): both hulls lose what the photos
    see through in the footprint hull (the sampling bounds), the same voxels; the surface the carving
    exposed takes the photos' colours again. Off (the default: README), the masks' hulls as they were."""
    cameras, images, masks, hull, _ = speckled_cup
    views = RefineViews.build([f"v{i}" for i in range(len(cameras))], cameras, images, masks)
    config = replace(RefineConfig(), hull_resolution=RESOLUTION, photo_carving=True, hollow_openings=False)
    plain_hulls = initial_fields.views_hulls(views, replace(config, photo_carving=False), RADIUS)
    plain, plain_footprint = plain_hulls.centres, plain_hulls.footprint
    assert plain_hulls.carving is None and plain_hulls.hollow is None and np.array_equal(plain.occupancy, hull)
    assert plain_hulls.sentences() == []
    hulls = initial_fields.views_hulls(views, config, RADIUS)
    carved, carved_footprint, carving = hulls.centres, hulls.footprint, hulls.carving
    assert hulls.hollow is None and hulls.sentences() == [carving.sentence()]
    # Carved from the footprint hull (the fatter: its layer over the opening goes too), the same voxels from both.
    removed = plain_footprint.occupancy & ~carved_footprint.occupancy
    assert carving.carved_voxels == removed.sum() > 100
    assert np.array_equal(hull & ~removed, carved.occupancy)
    assert (hull & removed).sum() > 100
    # The opening's new floor is coloured (the lid's colour sums went with it).
    floor = np.argwhere(carved.occupancy & ndimage.binary_dilation(removed) & ~removed)
    assert (carved.weight[tuple(floor.T)] > 0).mean() > 0.5
