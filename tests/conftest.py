"""Fixtures shared by all tests: the real test data beside the repository, and GL contexts."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("LIRM_SHARED_DATA", REPO_ROOT.parent / "shared" / "data"))

# Under pytest-xdist each worker is one process of several sharing the cores: one thread each (and
# for the processes the tests start), since two processes of two OpenMP threads on two cores thrash.
if os.environ.get("PYTEST_XDIST_WORKER"):
    for _name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[_name] = "1"
    import torch

    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (or $LIRM_SHARED_DATA); tests that need it skip with the reason when absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real test data not found at {SHARED_DATA} (set LIRM_SHARED_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def gl_context():
    """One headless EGL context for the whole session (creating contexts is slow on llvmpipe)."""
    from lirm.renderer.context import create_headless_context

    ctx = create_headless_context()
    yield ctx
    ctx.release()


@pytest.fixture(scope="session")
def renderer(gl_context):
    """One PBRRenderer for the whole session (program compilation is slow on llvmpipe)."""
    from lirm.renderer.pbr_renderer import PBRRenderer

    r = PBRRenderer(gl_context)
    yield r
    r.release()


@pytest.fixture(scope="session")
def x_display():
    """An X display for window tests: $DISPLAY if set, else a private Xvfb started for the session."""
    import shutil
    import subprocess

    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    if shutil.which("Xvfb") is None:
        pytest.skip("no X display and no Xvfb (apt-get install xvfb; `make setup` installs it)")
    read_fd, write_fd = os.pipe()
    proc = subprocess.Popen(
        ["Xvfb", "-displayfd", str(write_fd), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
        pass_fds=(write_fd,), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    os.close(write_fd)
    with os.fdopen(read_fd) as pipe:
        number = pipe.readline().strip()  # Xvfb writes the display number once it accepts clients
    if not number:
        proc.kill()
        pytest.skip("Xvfb did not start")
    display = f":{number}"
    os.environ["DISPLAY"] = display
    try:
        yield display
    finally:
        os.environ.pop("DISPLAY", None)
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="session")
def lego_capture(tmp_path_factory, shared_data) -> Path:
    """A prepared capture of 8 lego renders with known poses and alpha masks (no COLMAP), 64 px crops.
    Tests that change it copy it first."""
    import shutil

    from lirm.engine.cli import main

    lego = shared_data / "synth_nerf_lego_train"
    root = tmp_path_factory.mktemp("rec")
    folder = root / "photos"
    folder.mkdir()
    for i in range(0, 40, 5):
        shutil.copy(lego / "train" / f"r_{i}.png", folder / f"r_{i}.png")
    assert main(["capture", str(folder), "-o", str(root / "capture"), "--masks", "alpha", "--size", "64",
                 "--poses", str(lego / "transforms_train.json"), "--reference-originals"]) == 0
    return root / "capture"
