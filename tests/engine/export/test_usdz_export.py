"""USDZ beside glb (issue 21, case 11): the same mesh and textures, read back with usd-core, and
usd-core's compliance checker (usdchecker's rules, ARKit's included) finds nothing."""

from __future__ import annotations

import io
import zipfile

import cv2
import numpy as np

from lirm.engine.export.export_asset import ExportConfig, export_field
from lirm.engine.export.field_mesh import MeshExtractionConfig
from lirm.engine.export.usdz_writer import check_usdz, read_usdz
from lirm.engine.model.analytic_fields import MaterialPattern, SphereField

CONFIG = ExportConfig(mesh=MeshExtractionConfig(resolution=64, face_budget=3000), texture_size=128)


def test_usdz_holds_the_glbs_mesh_and_textures_and_passes_the_checker(tmp_path, gl_context):
    field = SphereField(sphere_radius=0.5, pattern=MaterialPattern())
    glb = export_field(field, tmp_path / "asset.glb", CONFIG, context=gl_context)
    usdz = export_field(field, tmp_path / "asset.usdz", CONFIG, context=gl_context)
    held = read_usdz(usdz.path)
    assert held["meshes"] == 1 and held["vertices"] == glb.vertices == usdz.vertices and held["faces"] == glb.faces
    assert held["textures"] == ["base_color.png", "metallic_roughness.png", "normal.png"]
    assert held["up_axis"] == "Y" and held["meters_per_unit"] == 1.0
    with zipfile.ZipFile(usdz.path) as archive:
        packed = cv2.imdecode(np.frombuffer(archive.read("base_color.png"), np.uint8), cv2.IMREAD_UNCHANGED)
        assert archive.namelist()[0].endswith(".usdc")  # the root layer first, as AR Quick Look requires
    assert np.array_equal(packed[..., ::-1], usdz.textures.base_color_srgb8())
    assert check_usdz(usdz.path) == []


def test_lirm_export_writes_a_usdz_by_its_name_and_beside_a_glb(lego_capture, tmp_path, capsys):
    import shutil

    from lirm.engine.cli import main

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "1", "--novel-views", "1", "--render-size", "24",
                 "--grid-resolution", "48"]) == 0
    small = ["--faces", "800", "--texture", "64", "--grid", "48"]
    assert main(["export", str(capture), "-o", str(tmp_path / "a.usdz"), *small]) == 0
    assert main(["export", str(capture), "-o", str(tmp_path / "b.glb"), "--usdz", *small]) == 0
    assert read_usdz(tmp_path / "a.usdz")["faces"] > 0 and (tmp_path / "b.usdz").is_file()
    assert check_usdz(tmp_path / "b.usdz") == []
