"""The window's state saved in a capture (app_state.json), without a window: every saved state reopens
(what cannot be restored is dropped, with a message), paths inside the capture are kept relative to it,
and absolute ones that an older version wrote into another capture are re-based (issue 21)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from lirm.app.actions import AppActions
from lirm.app.app_state import BUILTIN_ENVIRONMENTS, CHANNELS, STATE_FILE, AppState, SavedChoices
from lirm.app.jobs import JobRunner


def _capture(folder: Path) -> Path:
    """Enough of a capture for the state file's paths: a folder with capture.json."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "capture.json").write_text("{}")
    return folder


def _reopen(capture: Path, data) -> AppState:
    (capture / STATE_FILE).write_text(json.dumps(data))
    state = AppState(capture_dir=capture)
    state.load_choices()
    return state


def _warnings(state: AppState) -> list[str]:
    return [m.text for m in state.messages if m.level != "info"]


def test_the_built_in_environments_are_the_renderers():
    from lirm.renderer.pbr_renderer import DISPLAY_CHANNELS
    from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS

    assert BUILTIN_ENVIRONMENTS == tuple(PROCEDURAL_ENVIRONMENTS)
    assert CHANNELS == (*DISPLAY_CHANNELS, "field")


@pytest.mark.parametrize("channel", CHANNELS)
@pytest.mark.parametrize("environment", BUILTIN_ENVIRONMENTS)
def test_every_channel_and_environment_reopens_as_saved(tmp_path, channel, environment):
    capture = _capture(tmp_path / "capture")
    state = AppState(capture_dir=capture)
    state.choices.view.channel, state.choices.view.environment = channel, environment
    state.choices.view.rotation_deg, state.choices.view.exposure_ev, state.choices.view.background = 90.0, -1.5, False
    state.choices.viewing_update, state.choices.selected = 2, ["0001", "0003"]
    state.save_choices()
    again = AppState(capture_dir=capture)
    again.load_choices()
    assert again.choices == state.choices and again.choices_restored and not again.messages


def test_paths_inside_the_capture_are_saved_relative_to_it(tmp_path):
    capture = _capture(tmp_path / "capture")
    (capture / "hdri").mkdir()
    (capture / "hdri" / "room.hdr").write_bytes(b"#?RADIANCE\n")
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    state = AppState(capture_dir=capture)
    state.choices.view.environment = str(capture / "hdri" / "room.hdr")
    state.choices.export.path = str(capture / "export" / "asset.glb")
    state.save_choices()
    saved = json.loads((capture / STATE_FILE).read_text())
    assert saved["view"]["environment"] == "hdri/room.hdr" and saved["export"]["path"] == "export/asset.glb"
    # A copy (cp -a) reads them as its own files.
    copy = tmp_path / "copy"
    shutil.copytree(capture, copy)
    again = AppState(capture_dir=copy)
    again.load_choices()
    assert again.choices.export.path == str(copy / "export" / "asset.glb")
    assert again.choices.view.environment == str(copy / "hdri" / "room.hdr") and not again.messages
    # A folder outside any capture stays as the user chose it; a relative path typed in is in the capture.
    state.choices.export.path = str(outside / "asset.glb")
    state.save_choices()
    assert json.loads((capture / STATE_FILE).read_text())["export"]["path"] == str(outside / "asset.glb")
    assert state.capture_path("out/x.glb") == capture / "out" / "x.glb"


def test_old_absolute_paths_into_another_capture_are_rebased_or_dropped(tmp_path):
    original = _capture(tmp_path / "capture")
    (original / "hdri").mkdir()
    (original / "hdri" / "room.hdr").write_bytes(b"#?RADIANCE\n")
    copy = tmp_path / "capture2"
    shutil.copytree(original, copy)
    old = {"view": {"environment": str(original / "hdri" / "room.hdr")}, "export": {"path": str(original / "export" / "asset.glb")}}
    state = _reopen(copy, old)
    assert state.choices.export.path == str(copy / "export" / "asset.glb")
    assert state.choices.view.environment == str(copy / "hdri" / "room.hdr")
    assert any("inside another capture" in w and str(original) in w for w in _warnings(state)), state.messages
    # The original moved away (`mv capture capture3`): a path into a folder that is gone is dropped (the
    # default, this capture's export/asset.glb, is used), with a message.
    moved = tmp_path / "capture3"
    original.rename(moved)
    state = _reopen(moved, {"export": {"path": str(original / "export" / "asset.glb")}, "view": {"channel": "albedo"}})
    assert state.choices.export.path == "" and state.choices.view.channel == "albedo"
    assert any("could not be restored" in w and "no longer exists" in w for w in _warnings(state)), state.messages


@pytest.mark.parametrize("section, key, bad", [
    (None, "selected", "0001"), (None, "selected", [1, 2]), (None, "viewing_update", "latest"), (None, "viewing_update", -1),
    (None, "auto_update", "yes"), (None, "refine_minutes", None), (None, "refine_materials", "on"), (None, "refine_carve_openings", 1),
    (None, "refine_material_network", "yes"), ("view", "channel", "xray"), ("view", "channel", 3),
    ("view", "environment", "moon"), ("view", "environment", "/nowhere/gone.hdr"), ("view", "environment", None),
    ("view", "rotation_deg", "north"), ("view", "exposure_ev", float("nan")), ("view", "exposure_ev", 1e9),
    ("view", "background", 1), ("view", "show_cameras", None), ("view", "show_coverage", "no"),
    ("export", "path", 7), ("export", "faces", -5), ("export", "faces", 2.5), ("export", "texture", "big"),
    ("export", "grid", True), ("export", "turntable_frames", 0), ("export", "fit_textures", "yes"), (None, "view", []),
    (None, "export", "asset.glb"),
])
def test_a_value_that_cannot_be_restored_is_dropped_with_a_message(tmp_path, section, key, bad):
    capture = _capture(tmp_path / "capture")
    good = {"selected": ["0002"], "viewing_update": 1, "auto_update": True, "refine_minutes": 2.0, "refine_materials": False,
            "refine_carve_openings": False, "refine_material_network": False,
            "view": {"channel": "normal", "environment": "overcast", "rotation_deg": 45.0, "exposure_ev": 1.0, "background": False,
                     "show_cameras": False, "show_coverage": True},
            "export": {"path": "export/mine.glb", "faces": 5000, "texture": 512, "grid": 128, "turntable_frames": 12,
                       "fit_textures": False},
            "from_a_newer_version": {"ignored": True}}
    data = json.loads(json.dumps(good))
    (data if section is None else data[section])[key] = bad
    state = _reopen(capture, data)
    defaults = SavedChoices()
    expected = _reopen(capture, good).choices
    # The bad value is back to its default (a whole section if the section itself is bad), the rest as saved.
    if section is None:
        setattr(expected, key, getattr(defaults, key))
    else:
        setattr(getattr(expected, section), key, getattr(getattr(defaults, section), key))
    assert state.choices == expected
    warnings = _warnings(state)
    assert len(warnings) == 1 and "could not be restored" in warnings[0] and "dropped" in warnings[0], warnings


@pytest.mark.parametrize("text", ["{not json", "[1, 2]", "null", '"field"'])
def test_a_state_file_that_is_not_a_json_object_gives_the_defaults(tmp_path, text):
    capture = _capture(tmp_path / "capture")
    (capture / STATE_FILE).write_text(text)
    state = AppState(capture_dir=capture)
    state.load_choices()
    assert state.choices == SavedChoices() and any("damaged" in w for w in _warnings(state))
    assert (capture / STATE_FILE).read_text() == text  # left for the user to see


def test_opening_drops_a_saved_state_it_cannot_show(lego_capture, tmp_path, monkeypatch):
    """Whatever goes wrong while the saved state is put back, the capture opens, with the defaults and a message."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    (capture / STATE_FILE).write_text(json.dumps({"view": {"channel": "field", "environment": "sky"}}))
    actions = AppActions(AppState(), JobRunner(log_dir=tmp_path / "logs"))
    failures = []

    def viewport(event: str) -> None:  # stands for a window that cannot show the restored state once
        if event == "capture" and actions.state.choices.view.channel == "field" and not failures:
            failures.append(event)
            raise RuntimeError("cannot show that")
    actions.listeners.append(viewport)
    assert actions.open_capture(capture)
    assert failures and actions.state.choices == SavedChoices() and actions.state.capture_dir == capture.resolve()
    assert any("could not be restored" in w and "cannot show that" in w for w in _warnings(actions.state))
