"""Where an exported capture asset stands (issue 21, case 9): its lowest point on glTF's ground
(y = 0), its base centred on the vertical axis, and the placement recorded in the file so that a
viewer can draw the capture's cameras where the asset is."""

from __future__ import annotations

import json
import shutil
import struct

import cv2
import numpy as np

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.cli import main
from lirm.engine.export.capture_export import standing_on_the_ground
from lirm.engine.export.glb_placement import read_placement


def _gltf(path) -> dict:
    data = path.read_bytes()
    length, _ = struct.unpack("<II", data[12:20])
    return json.loads(data[20:20 + length])


def test_standing_on_the_ground_moves_the_lowest_point_to_zero_and_centres_the_base():
    rng = np.random.default_rng(0)
    body = rng.uniform([-0.3, -0.3, -0.5], [0.3, 0.3, 0.4], (500, 3))
    handle = rng.uniform([0.3, -0.05, 0.0], [0.6, 0.05, 0.3], (100, 3))  # off to one side, above the base
    vertices = np.vstack([body, handle, [[0.3, 0.3, -0.5], [-0.3, -0.3, -0.5]]])
    transform = np.diag([2.0, 2.0, 2.0, 1.0])
    transform[:3, 3] = (1.0, -1.0, 0.37)
    placed = vertices @ standing_on_the_ground(transform, vertices)[:3, :3].T + standing_on_the_ground(transform, vertices)[:3, 3]
    assert abs(placed[:, 2].min()) < 1e-9
    base = placed[placed[:, 2] < 0.02 * np.ptp(placed[:, 2])]
    assert np.allclose(0.5 * (base[:, :2].min(0) + base[:, :2].max(0)), 0.0, atol=1e-9)  # not pulled by the handle


def test_an_exported_capture_stands_on_y_zero(lego_capture, tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "1", "--preset", "tiny", "--novel-views", "1",
                 "--render-size", "24", "--grid-resolution", "48"]) == 0
    out = tmp_path / "asset.glb"
    assert main(["export", str(capture), "-o", str(out), "--faces", "2000", "--texture", "64", "--grid", "64"]) == 0
    gltf = _gltf(out)
    position = gltf["accessors"][gltf["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert abs(position["min"][1]) < 1e-6  # glTF is +Y up
    recorded = np.array(gltf["scenes"][0]["extras"]["lirm_world_from_field"])
    assert recorded.shape == (4, 4) and np.allclose(recorded[3], (0, 0, 0, 1))
    assert np.array_equal(read_placement(out), recorded)  # what the app draws the cameras and field with
    assert read_placement(tmp_path / "missing.glb") is None


def test_a_stated_height_exports_in_metres(lego_capture, tmp_path, capsys):
    """Issue 21, case 8: `lirm capture --real-size height=9.5cm` and every export is in metres."""
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "1", "--preset", "tiny", "--novel-views", "1",
                 "--render-size", "24", "--grid-resolution", "48"]) == 0
    out = tmp_path / "asset.glb"
    export = ["export", str(capture), "-o", str(out), "--faces", "800", "--texture", "64", "--grid", "48"]
    assert main(export) == 0
    assert "the scale is arbitrary" in capsys.readouterr().out
    assert main(["capture", "--real-size", "height=9.5cm", str(capture)]) == 0
    assert main(export) == 0
    assert "in metres: the object's height is 0.095 m" in capsys.readouterr().out
    position = (g := _gltf(out))["accessors"][g["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    assert abs(position["max"][1] - position["min"][1] - 0.095) < 1e-6 and abs(position["min"][1]) < 1e-6
    assert main(["capture", "--real-size", "tall", str(capture)]) == 2


def test_the_photos_cameras_render_an_export_where_its_photos_see_the_object(lego_capture, tmp_path, capsys, shared_data):
    """`lirm render ASSET --cameras CAPTURE`: the photos' cameras moved to where the export stood the
    asset, so each render lines up with its photo (a short refinement from the masks' hull)."""
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["refine", str(capture), "--iterations", "40"]) == 0
    out = tmp_path / "asset.glb"
    assert main(["export", str(capture), "-o", str(out), "--faces", "4000", "--texture", "64", "--grid", "96"]) == 0
    renders = tmp_path / "renders"
    assert main(["render", str(out), "--cameras", str(capture), "-o", str(renders), "--supersample", "1"]) == 0
    opened = Capture.open(capture)
    for frame, mask_file in zip(sorted(opened.cameras), sorted((renders / "mask").glob("*.png"))):
        rendered = cv2.imread(str(mask_file), cv2.IMREAD_GRAYSCALE) > 127
        photo = opened.read_mask(frame) > 127
        assert (rendered & photo).sum() / (rendered | photo).sum() > 0.7, frame
    capsys.readouterr()
    assert main(["render", str(out), "--cameras", str(tmp_path), "-o", str(tmp_path / "r2")]) != 0
    assert "not a capture (no capture.json)" in capsys.readouterr().err
    another_tools = shared_data / "pbr_models" / "Avocado_tex256.glb"  # no placement recorded
    assert main(["render", str(another_tools), "--cameras", str(capture), "-o", str(tmp_path / "r3")]) != 0
    assert "does not say where it was placed" in capsys.readouterr().err
