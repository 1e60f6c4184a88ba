"""The command line as a new user meets it (issue 21, case 12 and the export caveat of case 14)."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from lirm.engine.cli import main

FAST = ["--preset", "tiny", "--novel-views", "1", "--render-size", "24", "--grid-resolution", "48"]


def test_version_prints_the_package_version():
    result = subprocess.run([sys.executable, "-m", "lirm.engine.cli", "--version"], capture_output=True, text=True)
    assert result.returncode == 0 and result.stdout.startswith("lirm (LIRM Studio) 0.")


def test_app_help_says_what_opens_by_default(capsys):
    with pytest.raises(SystemExit):
        main(["app", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "default: the last capture opened" in text and "with --new" in text


def test_reconstruct_on_a_photo_folder_suggests_a_capture_that_works(tmp_path, shared_data, capsys):
    photos = tmp_path / "photos"
    photos.mkdir()
    shutil.copy(shared_data / "synth_nerf_lego_train" / "train" / "r_0.png", photos / "r_0.png")
    assert main(["reconstruct", str(photos)]) == 3
    err = capsys.readouterr().err
    suggested = tmp_path / "photos_capture"
    assert f"lirm capture {photos} -o {suggested}" in err and not suggested.exists()


def test_adding_only_skipped_photos_says_nothing_ran(lego_capture, tmp_path, shared_data, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    again = tmp_path / "again"
    again.mkdir()
    shutil.copy(shared_data / "synth_nerf_lego_train" / "train" / "r_0.png", again / "r_0.png")  # already in it
    capsys.readouterr()
    assert main(["capture", "--add", str(again), str(capture)]) == 0
    out = capsys.readouterr().out
    assert "nothing new was added" in out and "seconds:" not in out


def test_export_defaults_to_the_capture_and_carries_the_weights_caveat(lego_capture, tmp_path, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "1", "--novel-views", "1", "--render-size", "24",
                 "--grid-resolution", "48"]) == 0
    capsys.readouterr()
    assert main(["export", str(capture), "--faces", "800", "--texture", "64", "--grid", "48"]) == 0
    captured = capsys.readouterr()
    assert (capture / "export" / "asset.glb").is_file() and str(capture / "export" / "asset.glb") in captured.out
    assert "about these weights" in captured.err
    assert "the scale is arbitrary" in captured.out  # no real size given: said plainly (issue 21, case 8)


@pytest.mark.parametrize("text", ["height=abc", "depth=0.1", "height=0", "height=5km"])
def test_a_real_size_that_cannot_be_read_is_a_usage_error(lego_capture, tmp_path, text, capsys):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    before = (capture / "capture.json").read_bytes()
    assert main(["capture", "--real-size", text, str(capture)]) == 2
    assert "--real-size" in capsys.readouterr().err and (capture / "capture.json").read_bytes() == before


def test_the_app_and_the_cli_export_on_the_same_grid():
    from lirm.app.app_state import ExportSettings
    from lirm.engine.cli import build_parser

    args = build_parser().parse_args(["export", "somewhere"])
    assert ExportSettings().grid == args.grid


def test_progress_reaches_a_log_file_as_it_happens(lego_capture, tmp_path):
    """`lirm reconstruct CAPTURE > log 2>&1`: progress lines are in the log while it runs (line
    progress when not on a terminal), not only at the end."""
    import time

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    log = tmp_path / "log.txt"
    with open(log, "w") as out:
        process = subprocess.Popen([sys.executable, "-m", "lirm.engine.cli", "reconstruct", str(capture), "--updates", "2",
                                    *FAST], stdout=out, stderr=subprocess.STDOUT)
        seen_while_running = ""
        while process.poll() is None:
            text = log.read_text()
            if "LIRM updates:" in text:
                seen_while_running = text
            time.sleep(0.2)
    assert process.returncode == 0
    assert "LIRM updates: 0" in seen_while_running  # the stage's first line, written before the run ended
    assert "LIRM updates: 2/2 update (100%)" in log.read_text()
    assert "\r" not in log.read_text()


def test_line_progress_writes_a_line_per_stage_and_at_most_one_per_interval():
    import io

    from lirm.engine.progress_lines import progress_bar

    out = io.StringIO()
    bar = progress_bar("crops", 100, unit="view", file=out, every=3600)
    for _ in range(100):
        bar.update(1)
    bar.close()
    lines = out.getvalue().splitlines()
    assert lines[0].startswith("crops: 0/100 view (0%)") and lines[-1].startswith("crops: 100/100 view (100%)")
    assert len(lines) <= 3
