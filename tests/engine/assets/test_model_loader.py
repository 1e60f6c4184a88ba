"""load_model on the real glTF sample models, on modified copies of them, and on small made-up files."""

from __future__ import annotations

import copy
import json
import logging
import struct

import numpy as np
import pytest
from PIL import Image

from lirm.engine.assets.gltf_document import read_gltf
from lirm.engine.assets.model_loader import LoadedModel, load_model
from lirm.engine.errors import AssetLoadError

GLB_MODELS = [
    "Avocado_tex256.glb",
    "WaterBottle_tex256.glb",
    "NormalTangentTest.glb",
    "ClearcoatWicker.glb",
    "pmndrs_bunny_untextured.glb",
    "pmndrs_suzi_untextured.glb",
]
HELMET_FILES = [
    "DamagedHelmet.gltf",
    "DamagedHelmet.bin",
    "Default_albedo.jpg",
    "Default_metalRoughness.jpg",
    "Default_normal.jpg",
    "Default_AO.jpg",
    "Default_emissive.jpg",
]


@pytest.fixture(scope="module")
def models(shared_data):
    return shared_data / "pbr_models"


@pytest.fixture(scope="module")
def helmet_path(models):
    return models / "DamagedHelmet_gltf" / "DamagedHelmet.gltf"


@pytest.fixture(scope="module")
def helmet(helmet_path) -> LoadedModel:
    return load_model(helmet_path)  # five 2048² JPEGs: decode once per module


def _helmet_copy(helmet_path, tmp_path, without: str):
    """The helmet folder as links in tmp_path, less one file (the shared data stays untouched)."""
    for name in HELMET_FILES:
        if name != without:
            (tmp_path / name).symlink_to(helmet_path.parent / name)
    return tmp_path / "DamagedHelmet.gltf"


def _write_glb(path, tree: dict, binary: bytes = b"") -> None:
    body = json.dumps(tree).encode()
    body += b" " * (-len(body) % 4)
    chunks = struct.pack("<II", len(body), 0x4E4F534A) + body
    if binary:
        binary += b"\0" * (-len(binary) % 4)
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    path.write_bytes(b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks)


def _edited_glb(src, dst, edit) -> None:
    doc = read_gltf(src)
    tree = copy.deepcopy(doc.json)
    edit(tree)
    _write_glb(dst, tree, doc.buffers[0])


_COMPONENT = {np.int8: 5120, np.uint8: 5121, np.int16: 5122, np.uint16: 5123, np.uint32: 5125, np.float32: 5126}
_TYPE = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4"}


def _make_glb(path, attributes: dict, indices=None, mode=4, node=None, normalized=()):
    """A one-primitive glb from numpy arrays (their dtype picks the componentType)."""
    binary, views, accessors = b"", [], []

    def add(array, normalize=False):
        nonlocal binary
        array = np.ascontiguousarray(array)
        views.append({"buffer": 0, "byteOffset": len(binary), "byteLength": array.nbytes})
        acc = {
            "bufferView": len(views) - 1,
            "componentType": _COMPONENT[array.dtype.type],
            "count": len(array),
            "type": _TYPE[1 if array.ndim == 1 else array.shape[1]],
        }
        if normalize:
            acc["normalized"] = True
        if array.dtype == np.float32 and array.ndim == 2 and array.shape[1] == 3 and len(array):
            acc["min"], acc["max"] = np.nanmin(array, 0).tolist(), np.nanmax(array, 0).tolist()
        accessors.append(acc)
        binary += array.tobytes() + b"\0" * (-array.nbytes % 4)
        return len(accessors) - 1

    prim = {"attributes": {k: add(v, k in normalized) for k, v in attributes.items()}, "mode": mode}
    if indices is not None:
        prim["indices"] = add(np.asarray(indices, np.uint32).reshape(-1))
    tree = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, **(node or {})}],
        "meshes": [{"name": "made", "primitives": [prim]}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
    _write_glb(path, tree, binary)
    return tree


def _up(gltf_xyz: np.ndarray) -> np.ndarray:
    """glTF +Y up -> our +Z up: (x, y, z) -> (x, -z, y)."""
    x, y, z = np.moveaxis(np.asarray(gltf_xyz), -1, 0)
    return np.stack([x, -z, y], axis=-1)


# ------------------------------------------------------------------------------- real models


@pytest.mark.parametrize("name", GLB_MODELS)
def test_every_sample_model_loads(models, name):
    model = load_model(models / name)
    assert model.source == models / name
    assert model.meshes and all(len(m.indices) > 0 for m in model.meshes)
    for mesh in model.meshes:
        assert np.isfinite(mesh.positions).all()
        assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-3)
        factors = (*mesh.material.base_color_factor, mesh.material.metallic_factor, mesh.material.roughness_factor)
        assert all(type(f) is float for f in factors)
    assert np.all(model.bounds[1] > model.bounds[0])


def test_helmet_has_one_mesh_with_all_five_textures(helmet):
    assert helmet.warnings == []
    assert len(helmet.meshes) == 1
    material = helmet.meshes[0].material
    for slot in material.TEXTURE_SLOTS:
        assert getattr(material, slot).shape == (2048, 2048, 3), slot
    assert material.emissive_factor == (1.0, 1.0, 1.0)
    assert material.name == "Material_MR"


def test_helmet_stands_up_in_z_with_its_visor_toward_minus_y(helmet, helmet_path):
    # The node rotates the Blender data +90° about X into glTF +Y up; we rotate again into +Z up:
    # mesh (x, y, z) -> glTF (x, -z, y) -> ours (x, -y, -z).
    raw = read_gltf(helmet_path).accessor(1)
    mesh = helmet.meshes[0]
    np.testing.assert_allclose(mesh.positions, raw * [1, -1, -1], atol=1e-6)
    lo, hi = helmet.bounds
    # Height (Z, glTF's Y) 1.80, width 1.89. Depth is 2.0 because the air hoses reach far back: the
    # helmet is NOT taller than deep, but the back (+Y, hoses) lies further out than the visor (-Y).
    np.testing.assert_allclose(helmet.bounds, [[-0.947, -0.813, -0.901], [0.942, 1.187, 0.901]], atol=2e-3)
    assert hi[1] > -lo[1] + 0.3
    # Its helmet dome (the topmost vertices) has normals pointing up.
    top = mesh.positions[:, 2] > hi[2] - 0.02
    assert (mesh.normals[top, 2] > 0.7).all()


def test_helmet_uvs_and_normals_match_the_raw_accessors(helmet, helmet_path):
    doc = read_gltf(helmet_path)
    attrs = doc.json["meshes"][0]["primitives"][0]["attributes"]
    mesh = helmet.meshes[0]
    # glTF's v (down from the image top) kept: DamagedHelmet's v lies in [1, 2], a flip would show.
    np.testing.assert_allclose(mesh.uvs, doc.accessor(attrs["TEXCOORD_0"]), atol=1e-6)
    raw_normals = doc.accessor(attrs["NORMAL"])
    raw_normals /= np.linalg.norm(raw_normals, axis=1, keepdims=True)  # the file's are unit to ~4e-5 only
    np.testing.assert_allclose(mesh.normals, raw_normals * [1, -1, -1], atol=1e-6)


def test_upright_models_are_taller_along_z(models):
    bottle = load_model(models / "WaterBottle_tex256.glb")
    extent = np.ptp(bottle.bounds, axis=0)
    assert extent[2] > 2 * extent[0] and extent[2] > 2 * extent[1]
    avocado = load_model(models / "Avocado_tex256.glb")
    extent = np.ptp(avocado.bounds, axis=0)
    assert extent[2] > 1.4 * max(extent[0], extent[1])
    assert avocado.bounds[0, 2] == pytest.approx(0.0, abs=1e-4)  # it stands on the ground plane


def test_avocado_tangents_come_from_the_file(models):
    path = models / "Avocado_tex256.glb"
    doc = read_gltf(path)
    attrs = doc.json["meshes"][0]["primitives"][0]["attributes"]
    mesh = load_model(path).meshes[0]
    # Node: 180° about Y, (x, y, z) -> (-x, y, -z); then +Z up.
    turn = np.array([-1.0, 1.0, -1.0])
    np.testing.assert_allclose(mesh.positions, _up(doc.accessor(attrs["POSITION"]) * turn), atol=1e-6)
    raw = doc.accessor(attrs["TANGENT"])
    np.testing.assert_allclose(mesh.tangents[:, :3], _up(raw[:, :3] * turn), atol=1e-5)
    np.testing.assert_array_equal(mesh.tangents[:, 3], raw[:, 3])


def test_clearcoat_is_reported_and_recorded(models, caplog):
    with caplog.at_level(logging.WARNING, logger="lirm"):
        model = load_model(models / "ClearcoatWicker.glb")
    assert len(model.warnings) == 1 and "KHR_materials_clearcoat" in model.warnings[0]
    assert "base metallic-roughness" in model.warnings[0]
    assert model.meshes[0].material.ignored_extensions == ["KHR_materials_clearcoat"]
    assert any("KHR_materials_clearcoat" in r.getMessage() for r in caplog.records if r.name == "lirm")


def test_bunny_factors_are_floats_from_the_json(models):
    material = load_model(models / "pmndrs_bunny_untextured.glb").meshes[0].material
    assert material.base_color_factor == pytest.approx((0.8, 0.8, 0.8, 1.0))  # trimesh says 204 (uint8)
    assert material.metallic_factor == 0.0 and material.roughness_factor == 0.5
    assert material.alpha_mode == "BLEND" and material.double_sided


def test_absent_factors_take_gltf_defaults(models):
    material = load_model(models / "pmndrs_suzi_untextured.glb").meshes[0].material
    assert material.base_color_factor == (1.0, 1.0, 1.0, 1.0)
    assert (material.metallic_factor, material.roughness_factor) == (1.0, 1.0)
    assert material.emissive_factor == (0.0, 0.0, 0.0)


def test_base_colour_keeps_alpha_and_data_textures_are_rgb(models):
    material = load_model(models / "Avocado_tex256.glb").meshes[0].material
    assert material.base_color_texture.shape == (256, 256, 4)  # its PNGs are RGBA
    assert material.metallic_roughness_texture.shape == (256, 256, 3)
    assert material.normal_texture.shape == (256, 256, 3)


# --------------------------------------------------------------------------- modified copies


def test_missing_normal_texture_loads_with_a_warning(helmet_path, tmp_path):
    model = load_model(_helmet_copy(helmet_path, tmp_path, without="Default_normal.jpg"))
    material = model.meshes[0].material
    assert material.normal_texture is None
    assert material.base_color_texture is not None and material.emissive_texture is not None
    assert material.emissive_factor == (1.0, 1.0, 1.0)
    assert len(model.warnings) == 1
    assert "Default_normal.jpg" in model.warnings[0] and "normal texture" in model.warnings[0]


def test_missing_emissive_texture_turns_emission_off(helmet_path, tmp_path):
    model = load_model(_helmet_copy(helmet_path, tmp_path, without="Default_emissive.jpg"))
    material = model.meshes[0].material
    assert material.emissive_texture is None
    assert material.emissive_factor == (0.0, 0.0, 0.0)
    assert "Default_emissive.jpg" in model.warnings[0] and "emissive" in model.warnings[0]


def test_missing_bin_is_an_error_naming_it(helmet_path, tmp_path):
    with pytest.raises(AssetLoadError, match="DamagedHelmet.bin"):
        load_model(_helmet_copy(helmet_path, tmp_path, without="DamagedHelmet.bin"))


def test_truncated_glb_is_an_error(models, tmp_path):
    data = (models / "Avocado_tex256.glb").read_bytes()
    (tmp_path / "cut.glb").write_bytes(data[: len(data) // 2])
    with pytest.raises(AssetLoadError, match="truncated"):
        load_model(tmp_path / "cut.glb")


def test_text_file_named_glb_is_an_error(tmp_path):
    (tmp_path / "notes.glb").write_text("these are my notes, not a model\n")
    with pytest.raises(AssetLoadError, match="not a binary glTF.*text"):
        load_model(tmp_path / "notes.glb")


def test_required_unsupported_extension_is_an_error(models, tmp_path):
    def require_draco(tree):
        tree["extensionsUsed"] = tree["extensionsRequired"] = ["KHR_draco_mesh_compression"]

    _edited_glb(models / "Avocado_tex256.glb", tmp_path / "draco.glb", require_draco)
    with pytest.raises(AssetLoadError, match="KHR_draco_mesh_compression.*re-export"):
        load_model(tmp_path / "draco.glb")


def test_emissive_strength_multiplies_the_emissive_factor(models, tmp_path):
    def strength(tree):
        tree["extensionsUsed"] = tree["extensionsRequired"] = ["KHR_materials_emissive_strength"]
        tree["materials"][0]["extensions"] = {"KHR_materials_emissive_strength": {"emissiveStrength": 4.0}}

    _edited_glb(models / "WaterBottle_tex256.glb", tmp_path / "bright.glb", strength)
    model = load_model(tmp_path / "bright.glb")
    assert model.warnings == []
    assert model.meshes[0].material.emissive_factor == (4.0, 4.0, 4.0)


def test_texture_transform_is_reported_for_the_material_using_it(models, tmp_path):
    def transform(tree):
        tree["extensionsUsed"] = ["KHR_texture_transform", "KHR_lights_punctual"]
        info = tree["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
        info["extensions"] = {"KHR_texture_transform": {"scale": [2, 2]}}

    _edited_glb(models / "Avocado_tex256.glb", tmp_path / "tiled.glb", transform)
    model = load_model(tmp_path / "tiled.glb")
    assert model.meshes[0].material.ignored_extensions == ["KHR_texture_transform"]
    assert len(model.warnings) == 2
    assert "KHR_texture_transform" in model.warnings[0] and "2256_Avocado_d" in model.warnings[0]
    assert "KHR_lights_punctual" in model.warnings[1] and "ignored" in model.warnings[1]


# ------------------------------------------------------------------------------ made-up files

TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)  # counter-clockwise seen from glTF +Z


def test_vertex_colours_become_linear_float_rgba(tmp_path):
    rgb = np.array([[255, 0, 0], [0, 128, 0], [0, 0, 51]], np.uint8)
    _make_glb(tmp_path / "c.glb", {"POSITION": TRIANGLE, "COLOR_0": rgb}, indices=[0, 1, 2], normalized={"COLOR_0"})
    colors = load_model(tmp_path / "c.glb").meshes[0].colors
    np.testing.assert_allclose(colors, np.concatenate([rgb / 255.0, np.ones((3, 1))], axis=1), atol=1e-6)
    assert colors.dtype == np.float32


def test_mirroring_node_flips_winding_and_tangent_sign(tmp_path):
    normals = np.tile(np.array([0, 0, 1], np.float32), (3, 1))
    tangents = np.tile(np.array([1, 0, 0, 1], np.float32), (3, 1))
    attrs = {"POSITION": TRIANGLE, "NORMAL": normals, "TANGENT": tangents}
    _make_glb(tmp_path / "m.glb", attrs, indices=[0, 1, 2], node={"scale": [-1, 1, 1]})
    mesh = load_model(tmp_path / "m.glb").meshes[0]
    p = mesh.positions[mesh.indices[0]]
    face_normal = np.cross(p[1] - p[0], p[2] - p[0])
    # glTF +Z is our -Y: the front face still faces the stored normal after the mirror.
    np.testing.assert_allclose(mesh.normals, [[0, -1, 0]] * 3, atol=1e-6)
    assert face_normal @ mesh.normals[0] > 0
    np.testing.assert_allclose(mesh.tangents, [[-1, 0, 0, -1]] * 3, atol=1e-6)


def test_primitive_without_normals_is_shaded_flat(tmp_path):
    fold = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    _make_glb(tmp_path / "f.glb", {"POSITION": fold}, indices=[0, 1, 2, 0, 3, 1])
    mesh = load_model(tmp_path / "f.glb").meshes[0]
    assert mesh.positions.shape == (6, 3)
    np.testing.assert_allclose(mesh.normals[:3], [[0, -1, 0]] * 3, atol=1e-6)  # glTF +Z face
    np.testing.assert_allclose(mesh.normals[3:], [[0, 0, 1]] * 3, atol=1e-6)  # glTF +Y face is up


def test_interleaved_buffer_and_data_uri(tmp_path):
    # POSITION and NORMAL interleaved with byteStride 24, in a base64 data URI of a .gltf.
    import base64

    normals = np.tile(np.array([0, 0, 1], np.float32), (3, 1))
    interleaved = np.concatenate([TRIANGLE, normals], axis=1).astype(np.float32).tobytes()
    tree = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": 3, "type": "VEC3"},
        ],
        "bufferViews": [{"buffer": 0, "byteLength": len(interleaved), "byteStride": 24}],
        "buffers": [
            {
                "byteLength": len(interleaved),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(interleaved).decode(),
            }
        ],
    }
    (tmp_path / "i.gltf").write_text(json.dumps(tree))
    mesh = load_model(tmp_path / "i.gltf").meshes[0]
    np.testing.assert_allclose(mesh.positions, _up(TRIANGLE), atol=1e-7)
    np.testing.assert_allclose(mesh.normals, [[0, -1, 0]] * 3, atol=1e-7)


def test_points_only_is_an_error(tmp_path):
    _make_glb(tmp_path / "p.glb", {"POSITION": TRIANGLE}, mode=0)
    with pytest.raises(AssetLoadError, match="no triangles"):
        load_model(tmp_path / "p.glb")


def test_nan_positions_are_an_error(tmp_path):
    bad = TRIANGLE.copy()
    bad[1, 0] = np.nan
    _make_glb(tmp_path / "n.glb", {"POSITION": bad}, indices=[0, 1, 2])
    with pytest.raises(AssetLoadError, match="NaN"):
        load_model(tmp_path / "n.glb")


def test_sparse_geometry_is_an_error(tmp_path):
    tree = _make_glb(tmp_path / "s.glb", {"POSITION": TRIANGLE}, indices=[0, 1, 2])
    doc = read_gltf(tmp_path / "s.glb")
    tree["accessors"][0]["sparse"] = {"count": 1, "indices": {}, "values": {}}
    _write_glb(tmp_path / "s.glb", tree, doc.buffers[0])
    with pytest.raises(AssetLoadError, match="sparse"):
        load_model(tmp_path / "s.glb")


def test_missing_file_and_unknown_format(tmp_path):
    with pytest.raises(AssetLoadError, match="not found"):
        load_model(tmp_path / "nothing.glb")
    (tmp_path / "model.stl").write_bytes(b"solid x\nendsolid x\n")
    with pytest.raises(AssetLoadError, match=r"\.gltf, \.glb, \.obj"):
        load_model(tmp_path / "model.stl")


# ----------------------------------------------------------------------------------------- OBJ


def _write_textured_obj(folder, texture=True):
    pixels = np.zeros((2, 4, 3), np.uint8)
    pixels[0] = (255, 0, 0)  # top row red, bottom row blue
    pixels[1] = (0, 0, 255)
    Image.fromarray(pixels).save(folder / "wood.png")
    texture_line = "map_Kd wood.png\n" if texture else "map_Kd gone.png\n"
    (folder / "box.mtl").write_text("newmtl wood\nKd 0.8 0.8 0.8\nNs 30\n" + texture_line)
    (folder / "box.obj").write_text(
        "mtllib box.mtl\n"
        "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
        "vt 0 0\nvt 1 0\nvt 0 1\n"
        "vn 0 0 1\n"
        "usemtl wood\n"
        "f 1/1/1 2/2/1 3/3/1\n"
    )
    return folder / "box.obj", pixels


def test_obj_with_mtl_and_png_texture(tmp_path):
    path, pixels = _write_textured_obj(tmp_path)
    model = load_model(path)
    assert model.warnings == []
    mesh = model.meshes[0]
    material = mesh.material
    np.testing.assert_array_equal(material.base_color_texture, pixels)
    assert material.metallic_factor == 0.0 and 0.0 < material.roughness_factor < 1.0
    assert material.base_color_factor == (1.0, 1.0, 1.0, 1.0)
    # OBJ is taken as +Y up: v (0, 1, 0) is our +Z.
    np.testing.assert_allclose(mesh.positions, _up(TRIANGLE), atol=1e-7)
    np.testing.assert_allclose(mesh.normals, [[0, -1, 0]] * 3, atol=1e-7)
    # OBJ's vt (0, 1) is the image top, which is v = 0 in our (glTF) convention.
    np.testing.assert_allclose(mesh.uvs, [[0, 1], [1, 1], [0, 0]], atol=1e-7)


def test_obj_with_missing_texture_warns(tmp_path):
    path, _ = _write_textured_obj(tmp_path, texture=False)
    model = load_model(path)
    assert model.meshes[0].material.base_color_texture is None
    assert model.meshes[0].material.base_color_factor == pytest.approx((0.8, 0.8, 0.8, 1.0))
    assert len(model.warnings) == 1 and "gone.png" in model.warnings[0]


def test_obj_with_only_lines_or_nan_is_an_error(tmp_path):
    (tmp_path / "lines.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2\n")
    with pytest.raises(AssetLoadError, match="no triangles"):
        load_model(tmp_path / "lines.obj")
    (tmp_path / "nan.obj").write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n")
    with pytest.raises(AssetLoadError, match="NaN"):
        load_model(tmp_path / "nan.obj")
    (tmp_path / "junk.obj").write_bytes(b"\x00\x01\xff\xfe" * 100)
    with pytest.raises(AssetLoadError):
        load_model(tmp_path / "junk.obj")
