"""Shared by the refinement tests: the views a refinement fits, rendered from an analytic field."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera
from lirm.engine.refine.refine_views import RefineViews


@pytest.fixture(scope="session")
def analytic_views():
    """(field, cameras) -> RefineViews: each camera's image and mask rendered from the analytic field."""
    def build(truth, cameras) -> RefineViews:
        images, masks = [], []
        for camera in cameras:
            out = render_camera(truth, camera, VolumeRenderConfig(samples_per_ray=128, numerical_normals=False))
            images.append(np.clip(out["colour"], 0, 1))
            masks.append(out["opacity"])
        return RefineViews.build([f"v{i}" for i in range(len(cameras))], cameras, np.stack(images), np.stack(masks))

    return build


class SphereTracedCup:
    """A speckled (or plain) cylindrical cup photographed from a ring of views, sphere-traced from its
    exact signed distance, so that every voxel a carving removes can be checked against the true solid.
    It stands on z = -0.6, 1.2 tall, outer radius 0.55, walls 0.08 thick; its opening `depth` deep
    (1.0: a floor 0.2 thick; a solid cylinder when not `hollow`)."""

    RADIUS = 1.0
    RESOLUTION = 48
    SIZE = 128

    def __init__(self, depth: float = 1.0):
        self.depth = depth

    def sdf(self, points: np.ndarray, hollow: bool = True) -> np.ndarray:
        radial = np.linalg.norm(points[..., :2], axis=-1)
        z = points[..., 2]

        def cylinder(r: float, z0: float, z1: float) -> np.ndarray:
            d = np.stack([radial - r, np.maximum(z0 - z, z - z1)], axis=-1)
            outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
            return outside + np.minimum(np.max(d, axis=-1), 0.0)

        outer = cylinder(0.55, -0.6, 0.6)
        if not hollow:
            return outer
        return np.maximum(outer, -cylinder(0.47, 0.6 - self.depth, 1.0))

    @staticmethod
    def speckle(points: np.ndarray, seed: int = 3) -> np.ndarray:
        """A solid texture: sparse dark speckles on pale glaze, the same from every view."""
        rng = np.random.default_rng(seed)
        grid = rng.random((40, 40, 40)).astype(np.float32)
        index = np.clip(((np.clip(np.nan_to_num(points), -1.0, 1.0) + 1.0) / 2.0 * 40).astype(int), 0, 39)
        dark = grid[index[..., 0], index[..., 1], index[..., 2]] > 0.8
        return np.where(dark, 0.15, 0.85)

    def shoot(self, hollow: bool, textured: bool, views: int = 12, elevation: float = 40.0):
        """Cameras, sRGB images (object on white) and masks of the cup."""
        from lirm.engine.cameras import orbit_cameras

        size = self.SIZE
        cameras = orbit_cameras(views, elevation, 3.2, size, size, 45.0)
        images, masks = [], []
        for camera in cameras:
            origins, directions = camera.pixel_rays()
            o, d = origins.reshape(-1, 3), directions.reshape(-1, 3)
            t = np.full(len(o), 1.5)
            for _ in range(160):
                t += 0.8 * self.sdf(o + t[:, None] * d, hollow)
            points = o + t[:, None] * d
            hit = np.abs(self.sdf(points, hollow)) < 2e-3
            shade = self.speckle(points) if textured else np.full(len(o), 0.85)
            grey = np.where(hit, shade, 1.0).reshape(size, size)
            images.append(np.repeat(grey[..., None], 3, axis=-1).astype(np.float32))
            masks.append(hit.reshape(size, size).astype(np.float32))
        return cameras, np.stack(images), np.stack(masks)

    def hull_of(self, cameras, images, masks) -> np.ndarray:
        from lirm.engine.evaluation.carved_hull import CarvedHull

        hull = CarvedHull(image_size=self.SIZE, resolution=self.RESOLUTION, radius=self.RADIUS)
        return hull.update_known(hull.initial_state(1), cameras, list(images), [m > 0.5 for m in masks]).occupancy

    def voxel_centres(self, index: np.ndarray) -> np.ndarray:
        return -self.RADIUS + (index + 0.5) * (2.0 * self.RADIUS / self.RESOLUTION)


@pytest.fixture(scope="session")
def sphere_traced_cup():
    """SphereTracedCup (the class: `sphere_traced_cup(depth=...)` for another opening)."""
    return SphereTracedCup
