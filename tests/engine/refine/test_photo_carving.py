"""The hull carved where the photos see through it: a speckled cup's opening opens, a solid keeps its
inside, and plain surfaces (no evidence) carve nothing. The photos are ray-traced here from an
exact signed distance, so every carved voxel can be checked against the true solid."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from lirm.engine.cameras import orbit_cameras
from lirm.engine.evaluation.carved_hull import CarvedHull
from lirm.engine.refine import initial_fields
from lirm.engine.refine.config import RefineConfig
from lirm.engine.refine.photo_carving import PhotoCarvingConfig, photo_carve_occupancy
from lirm.engine.refine.refine_views import RefineViews

RADIUS = 1.0
RESOLUTION = 48
SIZE = 128


def cup_sdf(points: np.ndarray, hollow: bool = True) -> np.ndarray:
    """A cylindrical cup standing on z = -0.6, 1.2 tall, outer radius 0.55, walls 0.08 thick, its
    opening 1.0 deep (a solid cylinder when not `hollow`)."""
    radial = np.linalg.norm(points[..., :2], axis=-1)
    z = points[..., 2]

    def cylinder(r: float, z0: float, z1: float) -> np.ndarray:
        d = np.stack([radial - r, np.maximum(z0 - z, z - z1)], axis=-1)
        outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
        return outside + np.minimum(np.max(d, axis=-1), 0.0)

    outer = cylinder(0.55, -0.6, 0.6)
    if not hollow:
        return outer
    return np.maximum(outer, -cylinder(0.47, -0.4, 1.0))


def speckle(points: np.ndarray, seed: int = 3) -> np.ndarray:
    """A solid texture: sparse dark speckles on pale glaze, the same from every view."""
    rng = np.random.default_rng(seed)
    grid = rng.random((40, 40, 40)).astype(np.float32)
    index = np.clip(((np.clip(np.nan_to_num(points), -1.0, 1.0) + 1.0) / 2.0 * 40).astype(int), 0, 39)
    dark = grid[index[..., 0], index[..., 1], index[..., 2]] > 0.8
    return np.where(dark, 0.15, 0.85)


def shoot(hollow: bool, textured: bool, views: int = 12, elevation: float = 40.0):
    """Cameras, sRGB images (object on white) and masks of the cup, sphere-traced."""
    cameras = orbit_cameras(views, elevation, 3.2, SIZE, SIZE, 45.0)
    images, masks = [], []
    for camera in cameras:
        origins, directions = camera.pixel_rays()
        o, d = origins.reshape(-1, 3), directions.reshape(-1, 3)
        t = np.full(len(o), 1.5)
        for _ in range(160):
            t += 0.8 * cup_sdf(o + t[:, None] * d, hollow)
        points = o + t[:, None] * d
        hit = np.abs(cup_sdf(points, hollow)) < 2e-3
        shade = speckle(points) if textured else np.full(len(o), 0.85)
        grey = np.where(hit, shade, 1.0).reshape(SIZE, SIZE)
        images.append(np.repeat(grey[..., None], 3, axis=-1).astype(np.float32))
        masks.append(hit.reshape(SIZE, SIZE).astype(np.float32))
    return cameras, np.stack(images), np.stack(masks)


def hull_of(cameras, images, masks) -> np.ndarray:
    hull = CarvedHull(image_size=SIZE, resolution=RESOLUTION, radius=RADIUS)
    return hull.update_known(hull.initial_state(1), cameras, list(images), [m > 0.5 for m in masks]).occupancy


def voxel_centres(index: np.ndarray) -> np.ndarray:
    return -RADIUS + (index + 0.5) * (2.0 * RADIUS / RESOLUTION)


@pytest.fixture(scope="module")
def speckled_cup():
    cameras, images, masks = shoot(hollow=True, textured=True)
    hull = hull_of(cameras, images, masks)
    return cameras, images, masks, hull, photo_carve_occupancy(hull, RADIUS, cameras, images, masks)


def test_the_masks_hull_caps_the_opening(speckled_cup):
    *_, hull, _ = speckled_cup
    inside_opening = voxel_centres(np.argwhere(hull))
    inside_opening = inside_opening[(np.linalg.norm(inside_opening[:, :2], axis=1) < 0.35) & (inside_opening[:, 2] > 0.3)]
    assert len(inside_opening) > 100  # the lid the carving is for


def test_the_speckled_cups_opening_is_carved_and_its_walls_kept(speckled_cup):
    *_, hull, carving = speckled_cup
    voxel = 2.0 * RADIUS / RESOLUTION
    removed = np.argwhere(hull & ~carving.occupancy)
    assert carving.carved_voxels == len(removed) > 0
    sdf = cup_sdf(voxel_centres(removed))
    # Nothing of the cup's solid goes (a voxel whose centre lies a voxel inside its walls), and every
    # carved voxel is empty or touches the surface.
    assert np.all(sdf > -voxel)
    assert np.mean(sdf > -0.5 * voxel) > 0.97
    # The opening's upper part, which the photos look into, is open: the cavity's voxels within 0.3
    # of the rim (the views from 40 degrees see that deep at its centre).
    centres = voxel_centres(np.argwhere(hull))
    cavity = (cup_sdf(centres) > voxel) & (np.linalg.norm(centres[:, :2], axis=1) < 0.47) & (centres[:, 2] > 0.3)
    kept = carving.occupancy[tuple(np.argwhere(hull)[cavity].T)]
    assert cavity.sum() > 100 and kept.mean() < 0.25, f"{kept.mean():.2f} of the cavity's top still filled"


def test_a_solid_keeps_its_inside():
    cameras, images, masks = shoot(hollow=False, textured=True, views=10)
    hull = hull_of(cameras, images, masks)
    carving = photo_carve_occupancy(hull, RADIUS, cameras, images, masks)
    voxel = 2.0 * RADIUS / RESOLUTION
    removed = voxel_centres(np.argwhere(hull & ~carving.occupancy))
    # Only where the hull stands off the true surface (the cone the 40-degree views leave above its top),
    # never within the solid.
    assert np.all(cup_sdf(removed, hollow=False) > -voxel)
    assert np.mean(cup_sdf(removed, hollow=False) > 0.0) > 0.9  # the hull above the top, which no view saw from above


def test_a_plain_cup_gives_no_evidence_and_keeps_its_lid():
    cameras, images, masks = shoot(hollow=True, textured=False, views=8)
    hull = hull_of(cameras, images, masks)
    carving = photo_carve_occupancy(hull, RADIUS, cameras, images, masks, PhotoCarvingConfig())
    assert carving.carved_voxels == 0 and carving.pixels_seeing_through == 0
    assert np.array_equal(carving.occupancy, hull)


def test_the_refinement_starts_from_the_carved_hulls(speckled_cup):
    """`views_hulls` (what `lirm refine` and the bench start from): both hulls lose what the photos
    see through in the footprint hull (the sampling bounds), the same voxels; the surface the carving
    exposed takes the photos' colours again. Off (the default: README), the masks' hulls as they were."""
    cameras, images, masks, hull, _ = speckled_cup
    views = RefineViews.build([f"v{i}" for i in range(len(cameras))], cameras, images, masks)
    config = replace(RefineConfig(), hull_resolution=RESOLUTION, photo_carving=True)
    plain, plain_footprint, none = initial_fields.views_hulls(views, replace(config, photo_carving=False), RADIUS)
    assert none is None and np.array_equal(plain.occupancy, hull)
    carved, carved_footprint, carving = initial_fields.views_hulls(views, config, RADIUS)
    # Carved from the footprint hull (the fatter: its layer over the opening goes too), the same voxels from both.
    removed = plain_footprint.occupancy & ~carved_footprint.occupancy
    assert carving.carved_voxels == removed.sum() > 100
    assert np.array_equal(hull & ~removed, carved.occupancy)
    assert (hull & removed).sum() > 100
    # The opening's new floor is coloured (the lid's colour sums went with it).
    floor = np.argwhere(carved.occupancy & ndimage.binary_dilation(removed) & ~removed)
    assert (carved.weight[tuple(floor.T)] > 0).mean() > 0.5
