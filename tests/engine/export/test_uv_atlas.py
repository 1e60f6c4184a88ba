import numpy as np
import pytest
import trimesh

from lirm.engine.errors import LirmUserError
from lirm.engine.export.uv_atlas import AtlasConfig, unwrap


def test_unwrap_gives_uvs_in_the_unit_square_and_unit_tangents():
    mesh = trimesh.creation.icosphere(3)
    uv = unwrap(mesh, AtlasConfig(texture_size=256))
    assert uv.uvs.min() >= 0 and uv.uvs.max() <= 1 and len(uv.faces) == len(mesh.faces)
    np.testing.assert_allclose(np.linalg.norm(uv.tangents[:, :3], axis=1), 1.0, atol=1e-5)
    assert np.abs(np.sum(uv.tangents[:, :3] * uv.normals, axis=1)).max() < 1e-4
    # Seams duplicate vertices but every position is one of the mesh's.
    assert len(uv.positions) >= len(mesh.vertices)


def test_degenerate_meshes_are_refused_with_a_clear_message():
    flat = trimesh.Trimesh(np.zeros((3, 3)), np.array([[0, 1, 2]]), process=False)
    with pytest.raises(LirmUserError, match="degenerate"):
        unwrap(flat)
    with pytest.raises(LirmUserError, match="no faces"):
        unwrap(trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int)))


def test_a_vertex_whose_faces_have_no_area_still_gets_a_unit_normal():
    # An icosphere with one extra face of zero area (its three vertices on a line outside the surface):
    # trimesh gives those vertices zero normals, which would render as NaN in the G-buffer.
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    n = len(sphere.vertices)
    line = np.array([[0.0, 0.0, 0.6], [0.0, 0.0, 0.7], [0.0, 0.0, 0.8]])
    mesh = trimesh.Trimesh(np.vstack([sphere.vertices, line]), np.vstack([sphere.faces, [[n, n + 1, n + 2]]]), process=False)
    assert np.linalg.norm(np.asarray(mesh.vertex_normals)[n:], axis=1).max() < 0.5  # the case being tested
    out = unwrap(mesh, AtlasConfig(texture_size=256))
    lengths = np.linalg.norm(out.normals, axis=1)
    assert np.isfinite(out.normals).all() and np.allclose(lengths, 1.0, atol=1e-4)
    assert np.isfinite(out.tangents).all()
