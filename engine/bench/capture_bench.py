"""`lirm bench capture`: seconds per capture stage and peak memory for N photos.

Each photo count runs in a fresh process (python -m lirm.engine.bench.capture_bench --child ...),
so the peak resident memory it reports belongs to that capture alone.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..capture.photo_formats import is_photo


@dataclass
class CaptureBenchConfig:
    photos: Path
    counts: tuple[int, ...] = (20, 60)
    max_side: int = 960
    masks: str = "auto"


@dataclass
class CaptureBenchResult:
    photos: str
    rows: list[dict] = field(default_factory=list)

    def table(self) -> str:
        from lirm.engine.capture.pipeline import STAGES

        head = f"  {'photos':>6} {'posed':>6} " + " ".join(f"{s:>9}" for s in STAGES) + f" {'total s':>8} {'peak MB':>8}"
        lines = [f"photos from: {self.photos}", "", "seconds per stage (wall clock, this machine)", head]
        for r in self.rows:
            t = r["timings"]
            lines.append(f"  {r['photos']:>6} {r['registered']:>6} " + " ".join(f"{t.get(s, float('nan')):>9.1f}" for s in STAGES)
                         + f" {r['total_seconds']:>8.1f} {r['peak_rss_mb']:>8.0f}")
        return "\n".join(lines)


def run_capture_bench(config: CaptureBenchConfig, progress=None) -> CaptureBenchResult:
    say = progress or (lambda message: None)
    photos = sorted(p for p in Path(config.photos).iterdir() if is_photo(p))
    result = CaptureBenchResult(str(config.photos))
    for n in config.counts:
        if n > len(photos):
            say(f"skipping {n}: only {len(photos)} photos in {config.photos}")
            continue
        say(f"capturing {n} photos in a fresh process")
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "result.json"
            cmd = [sys.executable, "-m", "lirm.engine.bench.capture_bench", "--child", str(config.photos), str(n),
                   str(config.max_side), config.masks, str(out)]
            proc = subprocess.run(cmd, capture_output=True, text=True)
            if proc.returncode != 0:
                raise RuntimeError(f"capture benchmark for {n} photos failed:\n{proc.stderr[-2000:]}")
            result.rows.append(json.loads(out.read_text()))
    return result


def _child(photos_dir: str, n: int, max_side: int, masks: str, out: str) -> None:
    from dataclasses import replace

    from lirm.engine.capture.pipeline import CaptureConfig, run_capture

    photos = sorted(p for p in Path(photos_dir).iterdir() if is_photo(p))[:n]
    with tempfile.TemporaryDirectory() as tmp:
        inputs = Path(tmp) / "photos"
        inputs.mkdir()
        for p in photos:
            os.symlink(p.resolve(), inputs / p.name)
        config = CaptureConfig(masks=masks)
        config = replace(config, ingest=replace(config.ingest, max_side=max_side))
        start = time.perf_counter()
        summary = run_capture(inputs, Path(tmp) / "capture", config)
        total = time.perf_counter() - start
        peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss + resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        Path(out).write_text(json.dumps({
            "photos": n, "registered": summary.registered, "masked": summary.masked, "prepared": summary.prepared,
            "timings": summary.capture.settings.get("timings", {}), "total_seconds": total, "peak_rss_mb": peak_kb / 1024.0,
        }))


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--child", nargs=5, metavar=("PHOTOS", "N", "MAX_SIDE", "MASKS", "OUT"), required=True)
    a = parser.parse_args()
    photos_dir, n, max_side, masks, out = a.child
    _child(photos_dir, int(n), int(max_side), masks, out)
