"""Marching cubes with its derived case table: closed, outward-wound meshes of the right size."""

import numpy as np
import pytest
import trimesh

from lirm.engine.export.marching_cubes import case_table, extract_mesh, marching_cubes


def _trimesh(mesh):
    return trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)


def test_every_case_has_a_closed_surface_piece():
    table = case_table()
    counts = (table[:, :, 0] >= 0).sum(axis=1)
    assert counts[0] == 0 and counts[255] == 0
    assert counts[1:255].min() >= 1 and counts.max() <= 5
    # A case and its complement cut the same edges.
    for case in range(1, 255):
        assert set(table[case][table[case] >= 0].ravel()) == set(table[255 - case][table[255 - case] >= 0].ravel())


def test_sphere_volume_area_and_winding():
    mesh = _trimesh(extract_mesh(lambda p: np.linalg.norm(p, axis=-1) - 0.6, 64, 1.0))
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(4 / 3 * np.pi * 0.6**3, rel=0.01)  # positive: wound outward
    assert mesh.area == pytest.approx(4 * np.pi * 0.6**2, rel=0.01)
    centres = mesh.triangles_center
    assert np.mean(np.sum(mesh.face_normals * centres, axis=1) > 0) > 0.99


def test_torus_and_box_union_keeps_its_topology():
    def sdf(p):
        q = np.stack([np.linalg.norm(p[:, :2], axis=-1) - 0.5, p[:, 2]], -1)
        return np.minimum(np.linalg.norm(q, axis=-1) - 0.15, np.abs(p - [0.3, 0.3, 0.3]).max(-1) - 0.2)

    for resolution in (17, 48):
        mesh = _trimesh(extract_mesh(sdf, resolution, 1.0))
        assert mesh.is_watertight and mesh.euler_number == 0  # genus 1


def test_random_fields_give_watertight_meshes():
    rng = np.random.default_rng(3)
    for _ in range(5):
        v = rng.normal(size=(10, 10, 10))
        v[[0, -1]] = 1.0
        v[:, [0, -1]] = 1.0
        v[:, :, [0, -1]] = 1.0
        mesh = _trimesh(marching_cubes(v, np.zeros(3), 1.0))
        assert mesh.is_watertight and mesh.volume > 0


def test_no_surface_gives_an_empty_mesh():
    assert len(extract_mesh(lambda p: np.ones(len(p)), 8, 1.0).faces) == 0
    assert len(extract_mesh(lambda p: -np.ones(len(p)), 8, 1.0).faces) == 0
