"""The depth-only pass against the full PBR renderer's depth (the reference path) and an analytic sphere."""

from __future__ import annotations

import numpy as np

from lirm.engine.cameras import orbit_camera
from lirm.renderer.depth_raster import DepthRasterizer
from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import RenderSettings
from lirm.renderer.primitives import uv_sphere


def test_depth_pass_matches_the_pbr_renderer_and_the_sphere(gl_context, renderer):
    mesh = uv_sphere(0.6, segments=96, center=(0.1, 0.0, 0.05))
    raster = DepthRasterizer(gl_context)
    depth_mesh = raster.upload(mesh.positions, mesh.indices.reshape(-1, 3))
    scene = renderer.upload([mesh])
    lighting = renderer.prepare_lighting(Environment(np.ones((16, 32, 3), np.float32)))
    try:
        for azimuth, elevation in ((0, 10), (130, 45), (250, -10)):
            camera = orbit_camera(azimuth, elevation, 2.5, 80, 60, 45.0)
            depth = raster.depth(depth_mesh, camera)
            assert depth.shape == (60, 80)
            reference = renderer.render_view(scene, camera, lighting, RenderSettings(supersample=1))
            inside = reference.mask > 0.999
            hit = depth > 0
            # Same pixels covered except along the silhouette (the PBR path's coverage is anti-aliased).
            assert (hit != (reference.mask > 0.5)).mean() < 0.01
            np.testing.assert_allclose(depth[inside & hit], reference.depth[inside & hit], rtol=1e-3, atol=1e-3)
            # And the true sphere: the first hit of each pixel's ray, measured along the camera's z axis.
            origins, directions = camera.pixel_rays()
            centre = np.array([0.1, 0.0, 0.05])
            oc = origins - centre
            b = np.sum(oc * directions, axis=-1)
            disc = b**2 - (np.sum(oc * oc, axis=-1) - 0.6**2)
            t = -b - np.sqrt(np.maximum(disc, 0))
            z = t * (directions @ camera.c2w[:3, 2])
            core = hit & (disc > 0.05)
            assert np.abs(depth[core] - z[core]).max() < 0.01  # facets of a 96-segment sphere
    finally:
        depth_mesh.release()
        raster.release()
        scene.release()
        lighting.maps.release()


def test_depth_pass_of_an_empty_mesh_is_empty(gl_context):
    raster = DepthRasterizer(gl_context)
    empty = raster.upload(np.zeros((0, 3)), np.zeros((0, 3), np.uint32))
    try:
        assert not raster.depth(empty, orbit_camera(0, 0, 2.0, 16, 16, 40.0)).any()
    finally:
        empty.release()
        raster.release()
