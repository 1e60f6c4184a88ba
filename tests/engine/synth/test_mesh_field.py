"""A field sampled from a textured mesh: signed distance by the nearest sample's normal, materials
from the textures."""

import numpy as np
import torch
import trimesh

from lirm.engine.synth.mesh_field import MeshSampledField
from lirm.renderer.material import PBRMaterial
from lirm.renderer.mesh import MeshData


def test_sphere_mesh_field_has_the_sphere_sdf_and_the_texture_materials():
    sphere = trimesh.creation.uv_sphere(radius=0.5, count=[48, 48])
    uv = np.asarray(sphere.visual.uv, np.float32) if hasattr(sphere.visual, "uv") else None
    vertices = np.asarray(sphere.vertices, np.float32)
    uvs = uv if uv is not None else np.stack([0.5 + np.arctan2(vertices[:, 1], vertices[:, 0]) / (2 * np.pi),
                                              0.5 - vertices[:, 2]], axis=1).astype(np.float32)
    # Texture: red on the left half of the image (u < 0.5), green on the right; roughness 0.2 | 0.8 likewise.
    base = np.zeros((8, 8, 3), np.uint8)
    base[:, :4, 0] = 255
    base[:, 4:, 1] = 255
    mr = np.zeros((8, 8, 3), np.uint8)
    mr[:, :4, 1], mr[:, 4:, 1] = 51, 204
    mr[..., 2] = 255
    material = PBRMaterial(base_color_texture=base, metallic_roughness_texture=mr)
    mesh = MeshData(vertices, np.asarray(sphere.faces, np.uint32), uvs=uvs, material=material)
    field = MeshSampledField([mesh], np.eye(4), samples=200_000)
    points = torch.tensor([[0.0, 0.0, 0.0], [0.7, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.0, 0.9]])
    np.testing.assert_allclose(field.sdf(points).numpy(), [-0.5, 0.2, -0.2, 0.4], atol=0.01)
    for point in ([0.0, 0.5, 0.0], [0.0, -0.5, 0.0]):  # away from the UV seam
        surface = field.sample(torch.tensor([[point]]))
        assert surface.metallic.item() == 1.0
        u = float(uvs[np.argmin(np.linalg.norm(vertices - point, axis=1)), 0])
        expect_red = u % 1.0 < 0.5
        albedo = surface.albedo[0, 0].numpy()
        assert (albedo[0] > 0.9) == expect_red and (albedo[1] > 0.9) != expect_red
        assert abs(surface.roughness.item() - (0.2 if expect_red else 0.8)) < 0.01
