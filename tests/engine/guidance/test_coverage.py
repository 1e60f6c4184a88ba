"""Coverage: the batched visibility test agrees with the per-camera one, occlusion included."""

from __future__ import annotations

import dataclasses

import numpy as np
import trimesh

from lirm.engine.cameras import orbit_camera
from lirm.engine.guidance.coverage import SurfaceCoverage
from lirm.engine.guidance.next_views import candidate_cameras


def _two_spheres() -> trimesh.Trimesh:
    """A big sphere hiding part of a small one behind it from some directions."""
    big = trimesh.creation.icosphere(3, radius=0.5)
    small = trimesh.creation.icosphere(2, radius=0.2)
    small.apply_translation([0.0, 0.75, 0.0])
    return trimesh.util.concatenate([big, small])


def test_batched_visibility_equals_one_camera_at_a_time(renderer):
    mesh = _two_spheres()
    coverage = SurfaceCoverage(renderer, mesh.vertices, mesh.faces, mesh.vertex_normals)
    try:
        front = [orbit_camera(a, 20.0, 2.5, 96, 96, 50.0) for a in (-30.0, 0.0, 30.0)]
        distorted = dataclasses.replace(orbit_camera(90.0, 10.0, 2.5, 96, 96, 50.0), distortion=np.array([-0.1, 0.02, 0.0, 0.0]))
        cameras = [c for _, _, c in candidate_cameras(front)] + [distorted, orbit_camera(10.0, 0.0, 2.0, 128, 96, 60.0)]
        cosines = coverage.view_cosines(cameras)
        one_by_one = [coverage._seen_with(c, coverage.depth_map(c)) for c in cameras]
        for camera, a, b in zip(cameras, cosines, one_by_one):
            np.testing.assert_allclose(a, b, atol=1e-12)
        # A point seen well is seen within 60 degrees: cosine 0.5-1; unseen is 0.
        assert set(np.unique(cosines[(cosines > 0) & (cosines < 0.5)])) == set() and cosines.max() <= 1.0 + 1e-9
        batched = coverage.seen_many(cameras)
        assert all(np.array_equal(s, c > 0) for s, c in zip(batched, cosines))
        # Occlusion matters here: from azimuth 0 (camera on -y) the big sphere hides the small one on +y;
        # from azimuth 180 it is in plain view.
        small = np.arange(len(mesh.vertices)) >= len(trimesh.creation.icosphere(3, radius=0.5).vertices)
        seen_counts = np.array([s[small].sum() for s in batched])
        assert seen_counts.max() > 0 and (seen_counts == 0).any()
    finally:
        coverage.release()


def test_a_coarse_occluder_sees_what_the_mesh_sees(renderer):
    """lirm suggest draws a 1500-face copy of the surface as the occluder: per candidate, the share of
    vertices seen stays within a point of what the full mesh gives."""
    from lirm.engine.guidance.suggest import occluding_coverage

    mesh = _two_spheres()
    mesh = trimesh.Trimesh(*trimesh.remesh.subdivide(mesh.vertices, mesh.faces))  # 6400 faces
    cameras = [c for _, _, c in candidate_cameras([orbit_camera(0.0, 20.0, 2.5, 96, 96, 50.0)])]
    full = SurfaceCoverage(renderer, mesh.vertices, mesh.faces, mesh.vertex_normals)
    coarse = occluding_coverage(renderer, mesh, 1500)
    try:
        assert len(coarse.points) == len(mesh.vertices)
        a = np.array([s.mean() for s in full.seen_many(cameras)])
        b = np.array([s.mean() for s in coarse.seen_many(cameras)])
        assert np.abs(a - b).max() < 0.01
    finally:
        full.release()
        coarse.release()
