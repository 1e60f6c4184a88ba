"""Export round trip on analytic fields: the .glb rendered by our renderer matches the field's own
volume rendering, and each baked channel lands in its glTF slot."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import torch

from lirm.engine.assets.model_loader import load_model
from lirm.engine.errors import LirmUserError
from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.metrics import psnr
from lirm.engine.model.analytic_fields import BoxField, MaterialPattern, SphereField
from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera
from lirm.engine.synth.object_views import protocol_cameras
from lirm.renderer.procedural_environments import make_procedural_environment

# A smooth surface: marching cubes bevels a box's sharp edges by up to a voxel, which alone costs a
# 96 px silhouette 3-4% IoU (measured 0.96 for a box at grid 96); the sphere carries the same patterns.
# Its albedo is smooth (three sinusoids): a checker's edges would measure the two renderers' different
# anti-aliasing (mip-mapped texture vs one ray per pixel), not the bake.
class SmoothAlbedo(MaterialPattern):
    def albedo(self, p: torch.Tensor) -> torch.Tensor:
        return 0.5 + 0.35 * torch.sin(torch.stack([4.0 * p[..., 0], 5.0 * p[..., 1] + 1.0, 3.0 * p[..., 2] + 2.0], dim=-1))


FIELD = SphereField(sphere_radius=0.55, pattern=SmoothAlbedo())
CONFIG = ExportConfig(mesh=MeshExtractionConfig(resolution=96, face_budget=5000), texture_size=512)


@pytest.fixture(scope="module")
def exported(tmp_path_factory, gl_context):
    path = tmp_path_factory.mktemp("export") / "box.glb"
    return export_field(FIELD, path, CONFIG, context=gl_context)


def _glb_json(path) -> dict:
    data = path.read_bytes()
    length, _ = struct.unpack("<II", data[12:20])
    return json.loads(data[20:20 + length])


def test_glb_has_the_pbr_material_slots(exported):
    doc = _glb_json(exported.path)
    material = doc["materials"][0]
    pbr = material["pbrMetallicRoughness"]
    assert {"baseColorTexture", "metallicRoughnessTexture"} <= set(pbr) and "normalTexture" in material
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    assert {"POSITION", "NORMAL", "TANGENT", "TEXCOORD_0"} <= set(attributes)
    assert len(doc["images"]) == 3 and all(i["mimeType"] == "image/png" for i in doc["images"])


def test_round_trip_matches_the_fields_own_rendering(exported, renderer):
    model = load_model(exported.path)
    assert not model.warnings
    cameras = protocol_cameras([30.0, 150.0, 260.0], [20.0, 40.0, -10.0], 96, 50.0, 1.0)
    lighting = renderer.prepare_lighting(make_procedural_environment("studio", width=128))
    scene = renderer.upload(model.meshes)
    try:
        for camera in cameras:
            mesh_view = renderer.render_view(scene, camera, lighting)
            field_view = render_camera(FIELD, camera, VolumeRenderConfig(samples_per_ray=256, beta=1 / 1000, numerical_normals=False))
            a, b = mesh_view.mask > 0.5, field_view["opacity"] > 0.5
            iou = (a & b).sum() / (a | b).sum()
            assert iou >= 0.98, iou
            inside = a & b & (mesh_view.mask > 0.999) & (field_view["opacity"] > 0.999)
            assert psnr(mesh_view.albedo, field_view["albedo"], inside) >= 30.0
            # Slots: roughness (G) ramps along x, metallic (B) is the +y half; a swap would fail both.
            assert np.abs(mesh_view.roughness - field_view["roughness"])[inside].mean() < 0.03
            assert np.mean((mesh_view.metallic > 0.5)[inside] == (field_view["metallic"] > 0.5)[inside]) > 0.97
    finally:
        scene.release()
        lighting.maps.release()


def test_bad_output_paths_are_refused_and_existing_files_kept(tmp_path, gl_context):
    box = BoxField(half=(0.4, 0.3, 0.25))
    assert export_field(box, tmp_path / "box.glb", CONFIG, context=gl_context).faces <= 5000
    with pytest.raises(LirmUserError, match="does not exist"):
        export_field(FIELD, tmp_path / "missing" / "a.glb", CONFIG, context=gl_context)
    with pytest.raises(LirmUserError, match="must be a .glb"):
        export_field(FIELD, tmp_path / "a.gltf", CONFIG, context=gl_context)
    (tmp_path / "a_file").write_text("not a folder")
    with pytest.raises(LirmUserError, match="is a file, not a folder"):
        export_field(FIELD, tmp_path / "a_file" / "a.glb", CONFIG, context=gl_context)
    (tmp_path / "folder.glb").mkdir()
    with pytest.raises(LirmUserError, match="it is a folder"):
        export_field(FIELD, tmp_path / "folder.glb", CONFIG, context=gl_context)
    existing = tmp_path / "keep.glb"
    existing.write_bytes(b"previous asset")
    read_only = tmp_path / "ro"
    read_only.mkdir()
    read_only.chmod(0o500)
    try:
        target = read_only / "a.glb"
        if not __import__("os").access(read_only, __import__("os").W_OK):  # root ignores permissions
            with pytest.raises(LirmUserError, match="cannot write"):
                export_field(FIELD, target, CONFIG, context=gl_context)
    finally:
        read_only.chmod(0o700)
    assert existing.read_bytes() == b"previous asset"
    # A failed export (nothing to extract) leaves the existing file as it was, and no stray files.
    from lirm.engine.export.field_mesh import NoSurfaceError

    with pytest.raises(NoSurfaceError):
        export_field(SphereField(sphere_radius=10.0), existing, CONFIG, context=gl_context)
    assert existing.read_bytes() == b"previous asset"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_exported_file_passes_the_khronos_validator(exported):
    from lirm.engine.export.gltf_validation import validate_gltf

    report = validate_gltf(exported.path)
    assert report.errors == 0, report.messages
    assert report.warnings == 0, report.messages


def test_obj_export_matches_the_glb(tmp_path, gl_context):
    import trimesh

    config = ExportConfig(mesh=MeshExtractionConfig(resolution=48, face_budget=1500), texture_size=128, obj=True)
    result = export_field(FIELD, tmp_path / "asset.glb", config, context=gl_context)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["asset.glb", "asset.mtl", "asset.obj", "asset_basecolor.png", "asset_metallic.png",
                     "asset_normal.png", "asset_roughness.png"]
    obj = trimesh.load(tmp_path / "asset.obj", force="mesh", process=False)
    glb = trimesh.load(tmp_path / "asset.glb", force="mesh", process=False)
    assert len(obj.faces) == len(glb.faces) == result.faces
    np.testing.assert_allclose(obj.bounds, glb.bounds, atol=1e-5)
