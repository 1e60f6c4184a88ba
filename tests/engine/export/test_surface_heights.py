"""The height map over the export's surface (surface_heights.py): where it moves each photo pixel's
read, and the export's vertices. Its fit against photos is tested with the other registration
(test_photo_registration.py)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.export.photo_registration import photo_sources
from lirm.engine.export.photo_texture_fit import TextureFitConfig
from lirm.engine.export.surface_heights import SurfaceHeights, displaced
from lirm.engine.export.uv_atlas import UVMesh


def test_the_heights_are_read_at_each_pixels_texel_and_move_it_along_its_parallax():
    uv = torch.tensor([[0.1, 0.1], [0.9, 0.9]])
    heights = SurfaceHeights(size=2, max_height=1.0, pixel_uv=uv)
    with torch.no_grad():
        heights.raw[0, 0, 0, 0] = float(np.arctanh(0.5))  # the cell at uv (0.25, 0.25): 0.5 high
    sources = photo_sources([np.zeros((2, 2))], np.zeros((1, 4, 4, 3)), np.ones((1, 4, 4)),
                            [np.array([[2.0, -1.0], [3.0, 3.0]])])
    offsets = heights.offsets(sources)
    np.testing.assert_allclose(offsets.detach().numpy(), [[1.0, -0.5], [0.0, 0.0]], atol=1e-5)
    assert heights.mean_height() == pytest.approx(0.25, abs=1e-5)
    with pytest.raises(ValueError, match="parallax"):
        heights.offsets(photo_sources([np.zeros((2, 2))], np.zeros((1, 4, 4, 3)), np.ones((1, 4, 4))))
    with pytest.raises(ValueError, match="register_heights"):
        TextureFitConfig(register_heights=1)


def test_the_export_moves_each_vertex_along_its_normal_by_the_height_at_its_texel():
    heights = np.zeros((4, 4), np.float32)
    heights[:, 2:] = 0.05  # the right half of the atlas raised
    mesh = UVMesh(positions=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
                  normals=np.array([[0, 0, 1], [0, 0, 1], [1, 0, 0]], np.float32),
                  uvs=np.array([[0.1, 0.5], [0.9, 0.5], [0.9, 0.1]], np.float32),
                  tangents=np.tile(np.float32([1, 0, 0, 1]), (3, 1)), faces=np.array([[0, 1, 2]], np.uint32))
    moved = displaced(mesh, heights)
    np.testing.assert_allclose(moved.positions, [[0, 0, 0], [1, 0, 0.05], [0.05, 1, 0]], atol=1e-6)
    assert moved.normals is mesh.normals and moved.uvs is mesh.uvs and moved.faces is mesh.faces
    np.testing.assert_allclose(mesh.positions[1], [1, 0, 0])  # the original is left as it was


def test_a_seams_copies_of_a_vertex_move_together():
    """xatlas splits a vertex on a seam into one copy per chart, at the same point: if each copy read
    its own chart's height the seam would open into a crack."""
    heights = np.zeros((4, 4), np.float32)
    heights[:, 2:] = 0.04
    mesh = UVMesh(positions=np.array([[0, 0, 0], [0, 0, 0], [1, 0, 0]], np.float32),
                  normals=np.tile(np.float32([0, 0, 1]), (3, 1)),
                  uvs=np.array([[0.1, 0.5], [0.9, 0.5], [0.9, 0.9]], np.float32),
                  tangents=np.tile(np.float32([1, 0, 0, 1]), (3, 1)), faces=np.array([[0, 2, 1]], np.uint32))
    moved = displaced(mesh, heights)
    np.testing.assert_allclose(moved.positions, [[0, 0, 0.02], [0, 0, 0.02], [1, 0, 0.04]], atol=1e-6)
