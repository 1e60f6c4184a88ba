"""User folders of models and environments: usable files kept, broken ones reported by name."""

from __future__ import annotations

import shutil

import pytest

from lirm.engine.errors import LirmUserError
from lirm.engine.synth.asset_folders import scan_environment_folder, scan_model_folder


def test_environment_folder_with_broken_files(tmp_path, shared_data):
    shutil.copy(shared_data / "envmaps" / "studio_small_03_1k.hdr", tmp_path / "good.hdr")
    (tmp_path / "empty.hdr").write_bytes(b"")
    (tmp_path / "text.exr").write_text("not an image")
    data = (shared_data / "envmaps" / "forest_slope_1k.hdr").read_bytes()
    (tmp_path / "truncated.hdr").write_bytes(data[:200])
    (tmp_path / "notes.txt").write_text("ignored: not an environment suffix")
    scan = scan_environment_folder(tmp_path)
    assert [p.name for p in scan.usable] == ["good.hdr"]
    problems = {p.name: why for p, why in scan.problems}
    assert set(problems) == {"empty.hdr", "text.exr", "truncated.hdr"}
    assert "empty" in problems["empty.hdr"]
    report = scan.report("environments")
    assert "1 usable environments, 3 skipped" in report and "truncated.hdr" in report


def test_model_folder_with_unsupported_models(tmp_path, shared_data):
    shutil.copy(shared_data / "pbr_models" / "Avocado_tex256.glb", tmp_path / "avocado.glb")
    (tmp_path / "fake.glb").write_bytes(b"glTF" + b"\x00" * 20)
    (tmp_path / "draco.gltf").write_text('{"asset": {"version": "2.0"}, "extensionsRequired": ["KHR_draco_mesh_compression"],'
                                        ' "extensionsUsed": ["KHR_draco_mesh_compression"]}')
    scan = scan_model_folder(tmp_path)
    assert [p.name for p in scan.usable] == ["avocado.glb"]
    problems = {p.name: why for p, why in scan.problems}
    assert set(problems) == {"fake.glb", "draco.gltf"}
    assert "draco" in problems["draco.gltf"].lower()


def test_a_folder_with_nothing_usable_stops_before_training(tmp_path):
    (tmp_path / "broken.hdr").write_bytes(b"#?RADIANCE\n")
    with pytest.raises(LirmUserError, match="no usable HDR environments.*broken.hdr"):
        scan_environment_folder(tmp_path)
    with pytest.raises(LirmUserError, match="no usable glTF models"):
        scan_model_folder(tmp_path)
    with pytest.raises(LirmUserError, match="not a folder"):
        scan_model_folder(tmp_path / "missing")
