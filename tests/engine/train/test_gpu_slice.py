"""The GPU slice's one command (engine/train/gpu_slice.sh), run here as its CPU dry run.

A GPU slice is lent now and then, for minutes; a slice that fails on a renamed option or a broken
resume is lost. So the exact script the device runs is run here with DEVICE=cpu: it must resume the
repository's `small` weights, train on, stop at its deadline, and bring back the split float16 copy
and the logs, and the joined copy must resume again, at a later step.
"""

import os
import subprocess
import sys
import tarfile
from pathlib import Path

import pytest

from lirm.engine.train.training_checkpoint import load_resume_point

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[3]
RESUME = ROOT / "resources" / "checkpoints" / "lirm-small-resume.safetensors"


@pytest.mark.skipif(not RESUME.exists(), reason="no `small` weights to resume in this checkout")
def test_a_slice_dry_run_resumes_trains_and_brings_back_weights_that_resume_later(tmp_path):
    out, work = tmp_path / "out", tmp_path / "work"
    # The deadline's SIGINTs spaced for this CPU's steps (the first took 48-79 s here; 2 s on the H200),
    # with room for a step on one thread beside another test (the suite's two workers): a step there took
    # over 45 s, and the 25 s grace it had before killed it before the slim copy was written.
    env = dict(os.environ, DEVICE="cpu", OUT=str(out), SLICE_WORK=str(work), BATCH_SCENES="1", WORKERS="1",
               STOP_MARGIN="120", STOP_GRACE="60", KILL_GRACE="30",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    # What an earlier call on the same machine left behind must not come back with this one's logs.
    (work / "run").mkdir(parents=True)
    (work / "run" / "metrics.csv").write_text("step,loss\n99999,1.0\n")
    (work / "bench_train.json").write_text("{}")
    # Output to a file, not a pipe: the script's deadline watchdog may outlive it by a few seconds.
    with open(tmp_path / "slice.log", "w") as log:
        # 190 s: the first SIGINT 120 s before the end, after 50-70 s of training, the second 60 s later.
        done = subprocess.run(["bash", "engine/train/gpu_slice.sh", "190"], cwd=ROOT, env=env, stdout=log,
                              stderr=subprocess.STDOUT, timeout=420)
    text = (tmp_path / "slice.log").read_text()
    assert done.returncode == 0, text[-3000:]
    assert "continuing stage 1 from step" in text, text[-3000:]

    parts = sorted(out.glob("slim.part*"))
    assert parts, text[-3000:]
    joined = tmp_path / "slim.safetensors"
    joined.write_bytes(b"".join(p.read_bytes() for p in parts))
    # AdamW's second moments come back beside it, and joined under the companion's name they resume too.
    moments = sorted(out.glob("adamv.part*"))
    assert moments, text[-3000:]
    companion = tmp_path / "slim.adam-v.safetensors"
    companion.write_bytes(b"".join(p.read_bytes() for p in moments))
    before, after = load_resume_point(RESUME, "small"), load_resume_point(joined, "small")
    assert after.stage == 1 and after.moments_dropped and after.second_moments
    assert after.step > before.step
    # What the repository keeps: fp16 weights and the 8-bit moments, at most 50 MB together.
    assert joined.stat().st_size + companion.stat().st_size <= 50 * 2**20
    assert len(list(out.iterdir())) <= 8  # what a device call brings back: at most 8 files

    with tarfile.open(out / "logs.tar.gz") as logs:
        names = {Path(n).name for n in logs.getnames()}
    assert {"log.txt", "metrics.csv", "stage1_run.json"} <= names, names
    assert "bench_train.json" not in names  # the earlier call's, not this one's (TRAIN_BENCH was not set)
    with tarfile.open(out / "logs.tar.gz") as logs:
        member = next(m for m in logs.getmembers() if Path(m.name).name == "metrics.csv")
        assert "99999," not in logs.extractfile(member).read().decode()
