"""`lirm refine` on a prepared capture (lego renders with known poses and alpha masks): the refined
state is one more step of the history that export, suggest and the app read like an update's; a new
refinement after a new update warm-starts from the last one; held-out views are scored; a cancelled
refinement leaves the history as it was."""

from __future__ import annotations

import json
import shutil

import pytest

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.cli import main
from lirm.engine.model.field_state import load_field_state
from lirm.engine.model.pretrained import load_model
from lirm.engine.reconstruction.refine_step import holdout_split, run_refine
from lirm.engine.refine.config import refine_preset
from lirm.engine.errors import LirmUserError

QUICK = ["--iterations", "12", "--novel-views", "1", "--render-size", "24"]
FAST_UPDATE = ["--preset", "tiny", "--novel-views", "1", "--render-size", "24", "--grid-resolution", "48"]


@pytest.fixture()
def capture(lego_capture, tmp_path):
    folder = tmp_path / "capture"
    shutil.copytree(lego_capture, folder)
    return folder


def test_holdout_split_keeps_every_kth_view_out():
    assert holdout_split(list("abcdefgh"), 4) == (list("abcefg"), list("dh"))
    assert holdout_split(list("abc"), None) == (list("abc"), [])
    with pytest.raises(LirmUserError, match="at least 2"):
        holdout_split(list("abc"), 1)
    with pytest.raises(LirmUserError, match="nothing to hold out"):
        holdout_split(list("abc"), 5)


@pytest.mark.slow
def test_refine_is_a_step_of_the_history_that_export_and_suggest_read(capture, tmp_path, capsys):
    from lirm.engine.export.gltf_validation import validate_gltf

    assert main(["refine", str(capture), "--init", "lirm"] + QUICK) == 3
    assert "no LIRM update to start from" in capsys.readouterr().err
    assert main(["refine", str(capture), "--init", "hull-lirm"] + QUICK) == 3
    assert "no LIRM update to take materials from" in capsys.readouterr().err
    assert main(["refine", str(capture), "--init", "hull", "--holdout-every", "4"] + QUICK) == 0
    out = capsys.readouterr().out
    assert "refinement 1 (from carved hull): 12 steps" in out and "held-out views" in out
    entry = Capture.open(capture).updates[0]
    assert entry["kind"] == "refine" and entry["started_from"] == "carved hull" and len(entry["held_out"]) == 2
    step_dir = capture / "reconstruction" / "update_01"
    record = json.loads((step_dir / "refine.json").read_text())
    assert record["steps"] == 12 and record["holdout"]["psnr"] > 5 and record["losses"]
    assert (step_dir / "view_00_colour.png").exists()
    field, extra = load_field_state(step_dir / "state.safetensors")
    assert extra["started_from"] == "carved hull" and field.planes.shape[-1] == refine_preset("default").plane_resolutions[-1]
    assert not list((capture / "reconstruction").glob(".building_*"))

    # A LIRM update after it goes on from the tokens (none yet: afresh); refining again warm-starts.
    frames = sorted(Capture.open(capture).cameras)
    assert main(["reconstruct", str(capture), "--frames", ",".join(frames[:4])] + FAST_UPDATE) == 0
    assert main(["refine", str(capture)] + QUICK) == 0
    assert "refinement 3 (from refinement 1 (warm start))" in capsys.readouterr().out
    kinds = [u.get("kind", "update") for u in Capture.open(capture).updates]
    assert kinds == ["refine", "update", "refine"]
    summary = json.loads((capture / "reconstruction" / "summary.json").read_text())
    assert [u["update"] for u in summary["updates"]] == [1, 2, 3]

    glb = tmp_path / "refined.glb"
    assert main(["export", str(capture), "-o", str(glb), "--faces", "2000", "--texture", "256", "--grid", "64"]) == 0
    assert validate_gltf(glb).errors == 0
    assert main(["export", str(capture), "--update", "1", "-o", str(tmp_path / "first.glb"), "--faces", "2000",
                 "--texture", "128", "--grid", "48"]) == 0
    capsys.readouterr()
    assert main(["suggest", str(capture), "--k", "2", "--heat-map", str(tmp_path / "heat.png")]) == 0
    assert "refinement 3" in capsys.readouterr().out


def test_refine_from_the_hull_with_the_updates_materials(capture, capsys):
    assert main(["reconstruct", str(capture), "--updates", "1"] + FAST_UPDATE) == 0
    assert main(["refine", str(capture), "--init", "hull-lirm"] + QUICK) == 0
    out = capsys.readouterr().out
    assert "(from carved hull with LIRM update 1's materials)" in out
    # By default the hull is carved where the photos see through it first (the lego's textured crooks), and said so.
    assert "note: the photos see through the masks' hull at" in out and "voxels carved" in out
    assert Capture.open(capture).updates[-1]["started_from"] == "carved hull with LIRM update 1's materials"
    # Asked not to, the hull stays as the masks make it.
    assert main(["refine", str(capture), "--init", "hull-lirm", "--no-carve-openings"] + QUICK) == 0
    assert "see through the masks' hull" not in capsys.readouterr().out


def test_light_lobes_need_the_materials_and_a_sane_count(capture, capsys):
    assert main(["refine", str(capture), "--light-lobes", "1"] + QUICK) == 2
    assert "add --materials" in capsys.readouterr().err
    assert main(["refine", str(capture), "--materials", "--light-lobes", "20"] + QUICK) == 2
    assert "0..8" in capsys.readouterr().err
    assert not (capture / "reconstruction" / "update_01").exists()


def test_a_cancelled_refinement_leaves_the_history_as_it_was(capture):
    assert main(["reconstruct", str(capture), "--updates", "1"] + FAST_UPDATE) == 0
    before = (capture / "capture.json").read_text()
    source = load_model(None, "tiny")
    config = refine_preset("fast", minutes=None, iterations=50)

    def cancel_in_the_middle(tick) -> None:
        if tick.step == 3:
            raise SystemExit("killed")  # not a KeyboardInterrupt: the process dies before the step is saved

    with pytest.raises(SystemExit):
        run_refine(capture, source, config, progress=cancel_in_the_middle)
    assert (capture / "capture.json").read_text() == before
    assert not list((capture / "reconstruction").glob(".building_*")) and not (capture / "reconstruction" / "update_02").exists()


@pytest.mark.slow
def test_refine_with_materials_fits_them_under_the_capture_lighting(capture, capsys):
    """`lirm refine --materials` (issue 19): from a tenth of the budget on, the PBR term is in the
    loss and falls, and the fitted lighting is saved beside the state; without a lighting estimate
    the refinement says so and fits as before."""
    import numpy as np

    from lirm.engine.lighting.capture_lighting import CaptureLighting, CaptureLightingConfig
    from lirm.renderer.procedural_environments import make_procedural_environment

    steps = ["--iterations", "60", "--novel-views", "1", "--render-size", "24", "--init", "hull"]
    assert main(["refine", str(capture), "--materials", "--light-lobes", "0"] + steps) == 0
    record = json.loads((capture / "reconstruction" / "update_01" / "refine.json").read_text())
    # It says why, in the capture stage's words (the lego's renders are cut-outs), not a fix that cannot work.
    assert any(note.startswith("no lighting estimate in the capture (no photo shows any background") for note in record["notes"])
    assert record["settings"]["light_lobes"] == 0
    observed = np.zeros((64, 128))
    observed[32:] = 5  # the lower half seen, as a capture's backgrounds see it
    # Read through plain sRGB, as a capture on a clipped white backdrop is (camera_response.py): the
    # refinement compares through the estimate's curve and records it for the export's texture fit.
    CaptureLighting(make_procedural_environment("studio", width=128), observed, np.zeros((64, 128)), 8,
                    CaptureLightingConfig(response="srgb")).save(capture)
    assert main(["refine", str(capture), "--materials"] + steps) == 0
    step = capture / "reconstruction" / "update_02"
    record = json.loads((step / "refine.json").read_text())
    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.export.capture_export import texture_fit_inputs

    entry = Capture.open(capture).updates[-1]
    assert entry["camera_response"] == "srgb" and texture_fit_inputs(Capture.open(capture), entry)[1].camera_response == "srgb"
    assert record["settings"]["light_lobes"] == 1  # one compact light by default
    pbr = [entry["pbr"] for entry in record["losses"] if "pbr" in entry]
    assert len(pbr) >= 2 and pbr[-1] < pbr[0], record["losses"]
    # The image-space material network is heard when its check on these photos passes, and the record says which.
    assert record["settings"]["material_network"] == "auto" and "the material network" in record["material_network"]
    heard = "material network used" in record["material_network"]
    assert any("image_metallic" in entry for entry in record["losses"]) == heard
    assert record["material_network"] in record["notes"]
    assert (step / "lighting.hdr").is_file() and (step / "lighting.png").is_file()
    # Its export fits the baked textures to the photos it was refined on, under that lighting, and
    # says how far the photometric error fell; --no-texture-fit keeps the field's own textures.
    import re

    export = ["--grid", "48", "--faces", "2000", "--texture", "128"]
    capsys.readouterr()
    assert main(["export", str(capture), "-o", str(capture / "fitted.glb")] + export) == 0
    fitted = re.search(r"textures fitted to (\d+) photos .* photometric error ([\d.]+) -> ([\d.]+)", capsys.readouterr().out)
    assert fitted, "the export did not fit its textures"
    assert int(fitted.group(1)) == len(json.loads((step / "refine.json").read_text())["frames"])
    assert float(fitted.group(3)) < float(fitted.group(2))
    assert main(["export", str(capture), "-o", str(capture / "baked.glb"), "--no-texture-fit"] + export) == 0
    assert "textures fitted" not in capsys.readouterr().out
    # --register-photos: each photo warped onto the export before the fit, which says by how much.
    assert main(["export", str(capture), "-o", str(capture / "registered.glb"), "--register-photos"] + export) == 0
    assert re.search(r"photos registered \(mean shift [\d.]+ px\)", capsys.readouterr().out)
    assert main(["export", str(capture), "-o", str(capture / "both.glb"), "--register-photos", "--no-texture-fit"] + export) == 2
    assert "leave out one of them" in capsys.readouterr().err and not (capture / "both.glb").exists()
    # --material-network on: the metallic and the albedo's colour held to the network's in every step of the
    # inverse rendering, whatever its check says; off: never.
    assert main(["refine", str(capture), "--material-network", "on"] + steps) == 2
    assert "add --materials" in capsys.readouterr().err
    assert main(["refine", str(capture), "--materials", "--material-network", "on"] + steps[:1] + ["20"] + steps[2:]) == 0
    record = json.loads((capture / "reconstruction" / "update_03" / "refine.json").read_text())
    assert record["settings"]["losses"]["image_metallic"] > 0 and record["settings"]["losses"]["image_albedo"] > 0
    pbr_steps = [entry for entry in record["losses"] if "pbr" in entry]
    assert pbr_steps and all("image_metallic" in e and "image_albedo" in e for e in pbr_steps), record["losses"]
    assert "as asked" in record["material_network"]
    assert main(["refine", str(capture), "--materials", "--material-network", "off"] + steps[:1] + ["20"] + steps[2:]) == 0
    record = json.loads((capture / "reconstruction" / "update_04" / "refine.json").read_text())
    assert record["material_network"] == "" and not any("image_metallic" in e for e in record["losses"])
