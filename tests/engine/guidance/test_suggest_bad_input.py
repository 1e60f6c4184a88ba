"""lirm suggest on captures a photographer can really produce: one photo, several photos from one
spot, a reconstruction with no surface: sensible suggestions with a message, never a crash."""

from __future__ import annotations

import json
import shutil

import numpy as np

from lirm.engine.cli import main


def _capture_from_lego(shared_data, tmp_path, names: list[str], same_pose: bool = False):
    lego = shared_data / "synth_nerf_lego_train"
    photos = tmp_path / "photos"
    photos.mkdir()
    transforms = json.loads((lego / "transforms_train.json").read_text())
    frames = {f"./train/{n}": f for f in transforms["frames"] for n in names if f["file_path"] == f"./train/{n}"}
    first = transforms["frames"][0]["transform_matrix"]
    for n in names:
        shutil.copy(lego / "train" / f"{n}.png", photos / f"{n}.png")
        if same_pose:  # as if the photographer never moved
            frames[f"./train/{n}"]["transform_matrix"] = first
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps({"camera_angle_x": transforms["camera_angle_x"], "frames": list(frames.values())}))
    capture = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(capture), "--masks", "alpha", "--size", "64", "--poses", str(poses),
                 "--reference-originals"]) == 0
    return capture


def test_one_view_gets_sent_round_the_object(shared_data, tmp_path, capsys):
    capture = _capture_from_lego(shared_data, tmp_path, ["r_0"])
    capsys.readouterr()
    assert main(["suggest", str(capture), "--k", "3"]) == 0
    captured = capsys.readouterr()
    assert "only one view so far" in captured.err
    assert "1. azimuth" in captured.out and "3. azimuth" in captured.out
    plan = json.loads((capture / "guidance" / "suggestions.json").read_text())
    assert len(plan["suggestions"]) == 3 and plan["coverage_after"] > plan["coverage_now"]
    first = plan["suggestions"][0]
    assert "Go round to the other side" in first["sentence"] or "°" in first["sentence"]
    surface = np.load(capture / "guidance" / "surface_coverage.npz")
    assert surface["cameras_seeing"].shape == (len(surface["vertices"]),) and surface["cameras_seeing"].max() == 1


def test_views_from_one_spot_are_called_out(shared_data, tmp_path, capsys):
    capture = _capture_from_lego(shared_data, tmp_path, ["r_0", "r_5", "r_10"], same_pose=True)
    capsys.readouterr()
    assert main(["suggest", str(capture), "--k", "2"]) == 0
    captured = capsys.readouterr()
    assert "all views were taken from about the same spot" in captured.err
    assert "2. azimuth" in captured.out


def test_a_reconstruction_without_surface_falls_back_to_the_bounding_sphere(lego_capture, tmp_path, capsys):
    import torch

    from lirm.engine.model.checkpoint import save_checkpoint
    from lirm.engine.model.config import preset
    from lirm.engine.model.lirm import LIRM

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    model = LIRM(preset("tiny"))
    with torch.no_grad():  # an SDF that is positive everywhere: the field is empty
        model.heads.sdf[-1].bias.fill_(5.0)
    empty = save_checkpoint(model, tmp_path / "empty.safetensors", metadata={"trained": True})
    assert main(["reconstruct", str(capture), "--updates", "1", "--checkpoint", str(empty), "--novel-views", "1",
                 "--render-size", "16", "--grid-resolution", "32"]) == 0
    capsys.readouterr()
    assert main(["suggest", str(capture), "--checkpoint", str(empty), "--k", "2"]) == 0
    captured = capsys.readouterr()
    assert "the reconstruction has no surface yet" in captured.err and "surface: bounding sphere" in captured.out
