"""The app's action layer without a window: the same calls the panels make, with real `lirm` jobs."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from lirm.app.actions import AppActions
from lirm.app.app_state import AppState
from lirm.app.jobs import JobRunner
from lirm.engine.reconstruction.session import spread_order


@pytest.fixture
def app(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    state = AppState()
    return AppActions(state, JobRunner(log_dir=tmp_path / "logs"))


def test_opening_what_is_not_a_capture_says_what_to_do(app, tmp_path):
    assert not app.open_capture(tmp_path / "nowhere")
    assert app.state.messages[-1].level == "error" and "lirm capture" in app.state.messages[-1].text
    assert app.state.capture_dir is None


def test_refine_runs_lirm_refine_with_the_panels_choices(app, tmp_path):
    app.state.capture_dir = tmp_path / "capture"
    live = tmp_path / "live.safetensors"
    args = app.refine_arguments(2.0, live)
    assert args[:2] == ["refine", str(tmp_path / "capture")] and args[args.index("--minutes") + 1] == "2"
    # By default: the materials, and the openings carved as `lirm refine` does on its own.
    assert "--materials" in args and "--no-carve-openings" not in args and "--material-network" not in args
    # The material network as `lirm refine` has it by default (heard when its check passes), or never.
    from lirm.engine.cli import build_parser
    assert build_parser().parse_args(args).material_network == "auto"
    app.state.choices.refine_material_network = False
    assert build_parser().parse_args(app.refine_arguments(2.0, live)).material_network == "off"
    app.state.choices.refine_materials = False
    app.state.choices.refine_carve_openings = False
    args = app.refine_arguments(0.5, live)
    assert "--materials" not in args and "--no-carve-openings" in args and "--material-network" not in args  # only with materials
    # The command line the job runs is one `lirm refine` takes.
    parsed = build_parser().parse_args(args)
    assert parsed.carve_openings is False and parsed.materials is False


@pytest.mark.slow
def test_updates_step_back_and_choices_survive_a_restart(app, lego_capture, tmp_path):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert app.open_capture(capture)
    frames = [f.frame_id for f in app.state.frames]
    # Nothing picked: the next unused views, spread over the object as `lirm reconstruct` splits them.
    assert app.next_views() == spread_order(frames, app.cameras)[:4] and app.next_views()[0] == frames[0]
    app.select_views([frames[6], frames[7], "nonsense"])
    assert app.state.choices.selected == [frames[6], frames[7]]
    job = app.run_update()
    assert job is not None and app.run_update() is None  # one update at a time
    app.jobs.wait()
    assert [u["frames"] for u in app.state.updates] == [[frames[6], frames[7]]]
    free = [f for f in frames if f not in (frames[6], frames[7])]
    assert app.state.choices.selected == [] and app.next_views() == spread_order(free, app.cameras, [frames[6], frames[7]])[:4]
    assert job.peak_memory_mb and job.peak_memory_mb > 50
    app.run_update()
    app.jobs.wait()
    assert len(app.state.updates) == 2 and app.state.preview_asset == app.preview_path(2)
    assert app.preview_path(2).is_file()
    # Step back to update 1 and go on: update 2 is set aside, the new one takes its place.
    app.step_back(1)
    assert app.state.viewing_update == 1
    app.select_views([frames[5]])
    app.run_update()
    app.jobs.wait()
    assert [u["frames"] for u in app.state.updates] == [[frames[6], frames[7]], [frames[5]]]
    assert list((capture / "reconstruction" / "set_aside").glob("*/update_02"))
    app.set_environment("overcast")
    app.set_channel("normal")
    from lirm.app.recent import last_capture

    assert last_capture() == capture.resolve()  # `lirm app` with no argument reopens it
    # A new session on the same capture opens where this one was.
    again = AppActions(AppState(), JobRunner(log_dir=tmp_path / "logs"))
    assert again.open_capture(capture)
    assert again.state.choices.view.environment == "overcast" and again.state.choices.view.channel == "normal"
    # A damaged state file: defaults, a warning, and the file left as it was for the user to see.
    (capture / "app_state.json").write_text("{not json")
    third = AppActions(AppState(), JobRunner(log_dir=tmp_path / "logs"))
    assert third.open_capture(capture)
    assert any("damaged" in m.text for m in third.state.messages) and third.state.choices.view.environment == "studio"
    assert (capture / "app_state.json").read_text() == "{not json"


@pytest.mark.slow
def test_a_box_redoes_one_views_mask(app, lego_capture, tmp_path):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    app.open_capture(capture)
    frame = app.state.frames[0].frame_id
    before = cv2.imread(str(capture / "masks" / f"{frame}.png"), cv2.IMREAD_GRAYSCALE)
    h, w = before.shape
    ys, xs = np.nonzero(before > 127)
    box = (xs.min() - 5, ys.min() - 5, xs.min() + (xs.max() - xs.min()) // 2, ys.max() + 5)  # the left half only
    assert app.fix_mask_with_box(frame, box) is not None
    app.jobs.wait()
    after = cv2.imread(str(capture / "masks" / f"{frame}.png"), cv2.IMREAD_GRAYSCALE)
    assert after.shape == (h, w) and (after > 127).sum() < 0.8 * (before > 127).sum()
    assert not (after[:, box[2] + 2:] > 127).any()  # nothing outside the box
    history = json.loads((capture / "capture.json").read_text())["history"]
    assert any(h["action"] == "fix mask" for h in history)
    assert app.fix_mask_with_box(frame, (10, 10, 12, 12)) is None  # too small: says so
    assert "larger box" in app.state.messages[-1].text


def test_the_real_height_set_in_the_app_reaches_the_capture(app, lego_capture, tmp_path):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert app.open_capture(capture)
    assert app.state.real_size is None
    assert app.set_real_size(0.0) is None  # says what to give instead
    assert app.set_real_size(0.12) is not None
    app.jobs.wait()
    assert json.loads((capture / "capture.json").read_text())["settings"]["real_size"] == {"height": 0.12}
    assert app.state.real_size == {"height": 0.12}


def test_an_import_whose_photos_were_exposed_apart_warns_with_the_fix(app, shared_data, tmp_path):
    """A phone's automatic exposure moved between shots (EXIF: 1/50 s against 1/200 s): after the
    import the app says so and how to avoid it, as `lirm capture`'s report does."""
    from PIL import Image
    from PIL.TiffImagePlugin import IFDRational

    from lirm.engine.cli import main

    lego = shared_data / "synth_nerf_lego_train"
    photos = tmp_path / "photos"
    photos.mkdir()
    for k, denominator in enumerate((100, 50, 200, 100)):
        exif = Image.new("RGB", (1, 1)).getexif()
        exif.get_ifd(0x8769).update({0x829A: IFDRational(1, denominator), 0x829D: IFDRational(18, 10), 0x8827: 100})
        Image.open(lego / "train" / f"r_{5 * k}.png").save(photos / f"r_{5 * k}.png", exif=exif.tobytes())
    capture = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(capture), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    app._say_exposure(capture)
    last = app.state.messages[-1]
    assert last.level == "warning" and last.text.startswith("exposure: 4 of 4 photos, 2.0 EV between"), last.text
    assert "lock the exposure" in last.text


def test_an_import_whose_backgrounds_say_the_exposure_moved_warns_with_the_fix(app, shared_data, tmp_path):
    """Photos without EXIF exposure whose shared backgrounds said they were exposed 1.1 EV apart (the
    capture's lighting stage writes that, exposure_estimate.py; written here on a capture of cut-outs)."""
    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.capture.exposure_match import ESTIMATED_EXPOSURE_KEY
    from lirm.engine.cli import main

    lego = shared_data / "synth_nerf_lego_train"
    photos = tmp_path / "photos"
    photos.mkdir()
    for k in range(3):
        (photos / f"r_{5 * k}.png").write_bytes((lego / "train" / f"r_{5 * k}.png").read_bytes())
    folder = tmp_path / "capture"
    assert main(["capture", str(photos), "-o", str(folder), "--masks", "alpha", "--size", "32",
                 "--poses", str(lego / "transforms_train.json")]) == 0
    app._say_exposure(folder)
    assert not any("exposure" in m.text for m in app.state.messages)  # cut-outs: nothing to estimate from
    capture = Capture.open(folder)
    stops = dict(zip(sorted(capture.frames), (0.4, -0.7, 0.3)))
    capture.settings[ESTIMATED_EXPOSURE_KEY] = {"stops": stops, "pairs": 3, "residual_stops": 0.02, "matched": True}
    capture.save()
    app._say_exposure(folder)
    last = app.state.messages[-1]
    assert last.level == "warning" and last.text.startswith("exposure, from the photos' backgrounds: 3 photos, 1.1 EV"), last.text
    assert "matched to the most exposed photo" in last.text and "lock the exposure" in last.text
