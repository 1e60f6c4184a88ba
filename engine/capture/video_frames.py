"""Frames from a video file or a live camera: sharp, well-spread stills for the capture.

Both sources are a cv2.VideoCapture and go through one reader loop, which only needs read() and
get(): a camera is a stream whose frame count is unknown, read for at most `max_seconds` or
`max_frames_read` frames. The stream is split into `target_frames` equal time bins and the sharpest
frame of each (variance of the Laplacian of a small grey copy) is kept; bins whose best frame is far
blurrier than the median are dropped, and so are frames nearly identical to the previous kept one
(the camera did not move). Memory stays bounded: only the current best frame per bin is held.

When the length is unknown, bins start one frame wide and adjacent pairs merge (keeping the sharper)
whenever there are more than 2 x target_frames of them; at the end they are regrouped into
target_frames equal bins over what was actually read. With a known length the bins are exact.

Frame records: origin "video" (original = the video file) or "camera" (original = the working copy,
the only copy there is); timestamp_s = frame index / fps; sha256 = of the working copy's bytes,
since a frame has no file of its own.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, Sequence

import cv2
import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write_bytes

from .ingest import (Cancel, Cancelled, Progress, ThumbnailIndex, cap_long_side, describe, encode_jpeg, next_frame_ids,
                     thumbnail)
from .records import FileReport, ImageRecord


@dataclass
class VideoConfig:
    target_frames: int = 24
    max_side: int = 1280  # working copies' long side
    jpeg_quality: int = 95
    analysis_side: int = 320  # sharpness is measured on a grey copy this size (noise-robust, fast)
    blur_ratio: float = 0.35  # drop a bin whose best frame is below this fraction of the median sharpness
    near_duplicate_tolerance: float | None = 4.0  # as in IngestConfig; None keeps still-camera frames
    max_seconds: float = 120.0
    max_frames_read: int = 7200
    fallback_fps: float = 30.0  # when the stream does not say


class FrameStream(Protocol):
    """What the reader loop needs; cv2.VideoCapture is one."""

    def read(self) -> tuple[bool, np.ndarray | None]: ...

    def get(self, prop_id: int) -> float: ...


@dataclass
class _Candidate:
    index: int  # frame number in the stream
    sharpness: float
    rgb: np.ndarray  # already capped at max_side, so the bins' memory is bounded


def sharpness(frame: np.ndarray, analysis_side: int) -> float:
    grey = frame if frame.ndim == 2 else cv2.cvtColor(frame, cv2.COLOR_BGRA2GRAY if frame.shape[2] == 4 else cv2.COLOR_BGR2GRAY)
    grey = cap_long_side(grey, analysis_side)
    return float(cv2.Laplacian(grey, cv2.CV_32F).var())


def select_video_frames(
    source: str | Path | int,
    capture_root: str | Path,
    config: VideoConfig = VideoConfig(),
    existing: Sequence[ImageRecord] = (),
    progress: Progress | None = None,
    cancel: Cancel | None = None,
    *,
    stop: Cancel | None = None,
) -> tuple[list[ImageRecord], list[FileReport]]:
    """A video file (path) or a camera (index) -> new frame records and reports.
    cancel() -> True abandons everything (raises Cancelled); stop() -> True ends reading early and
    keeps the frames so far (a camera's Stop button). Raises LirmUserError naming the source when it
    cannot be opened or yields no frame."""
    if isinstance(source, int):
        name, origin, video_path = Path(f"camera {source}"), "camera", None
        stream = cv2.VideoCapture(source)
        advice = "check that the camera is connected and not in use by another program"
    else:
        name = video_path = Path(source)
        origin = "video"
        if "://" not in str(source) and not video_path.is_file():
            raise LirmUserError(f"{video_path}: no such video file")
        stream = cv2.VideoCapture(str(source))
        advice = "the file may be damaged or use a codec OpenCV cannot decode; convert it to MP4 (H.264)"
    try:
        if not stream.isOpened():
            raise LirmUserError(f"{name}: cannot be opened; {advice}")
        return select_stream_frames(stream, capture_root, name=name, origin=origin,
                                    original=video_path.resolve() if video_path is not None and video_path.exists() else video_path,
                                    config=config, existing=existing, progress=progress, cancel=cancel, stop=stop,
                                    advice=advice)
    finally:
        stream.release()


def select_stream_frames(
    stream: FrameStream,
    capture_root: str | Path,
    *,
    name: Path,
    origin: str,
    original: Path | None,
    config: VideoConfig = VideoConfig(),
    existing: Sequence[ImageRecord] = (),
    progress: Progress | None = None,
    cancel: Cancel | None = None,
    stop: Cancel | None = None,
    advice: str = "",
) -> tuple[list[ImageRecord], list[FileReport]]:
    """The reader loop for any open stream. `original` None means the working copy is the original."""
    capture_root = Path(capture_root)
    fps = _positive(stream.get(cv2.CAP_PROP_FPS)) or config.fallback_fps
    count = _positive(stream.get(cv2.CAP_PROP_FRAME_COUNT))
    limit = max(1, min(config.max_frames_read, math.floor(config.max_seconds * fps)))
    horizon = min(int(count), limit) if count else None
    candidates, n_read = _best_per_bin(stream, config, limit, horizon, progress, cancel, stop)
    if n_read == 0:
        raise LirmUserError(f"{name}: no frame could be read" + (f"; {advice}" if advice else ""))
    return _write_selection(candidates, n_read, fps, capture_root, name, origin, original, config, existing)


def _positive(value: float) -> float | None:
    return value if value is not None and math.isfinite(value) and 0 < value < 1e9 else None


def _best_per_bin(stream, config, limit, horizon, progress, cancel, stop) -> tuple[list[_Candidate], int]:
    """Read the stream once; return the sharpest frame per equal time bin (in time order)."""
    target = config.target_frames
    width = horizon / target if horizon else 1.0  # fine-bin width in frames
    bins: dict[int, _Candidate] = {}
    n_read = 0
    while n_read < limit:
        if cancel is not None and cancel():
            raise Cancelled("cancelled while reading the video")
        if stop is not None and stop():
            break
        ok, frame = stream.read()
        if not ok or frame is None:
            break
        index, n_read = n_read, n_read + 1
        score = sharpness(frame, config.analysis_side)
        k = math.floor(index / width + 1e-9)
        if k not in bins or score > bins[k].sharpness:
            bins[k] = _Candidate(index, score, cap_long_side(_to_rgb(frame), config.max_side))
        while len(bins) > 2 * target:  # only when the length is unknown: coarsen, keep the sharper of each pair
            width *= 2
            merged: dict[int, _Candidate] = {}
            for k_old in sorted(bins):
                c = bins[k_old]
                if k_old // 2 not in merged or c.sharpness > merged[k_old // 2].sharpness:
                    merged[k_old // 2] = c
            bins = merged
        if progress is not None:
            progress(n_read, max(n_read, horizon or limit))
    # Regroup the fine bins into target equal bins over what was actually read.
    coarse_width = n_read / target
    coarse: dict[int, _Candidate] = {}
    for k in sorted(bins):
        j = min(target - 1, math.floor(k * width / coarse_width + 1e-9))
        if j not in coarse or bins[k].sharpness > coarse[j].sharpness:
            coarse[j] = bins[k]
    return [coarse[j] for j in sorted(coarse)], n_read


def _to_rgb(frame: np.ndarray) -> np.ndarray:
    if frame.ndim == 2:
        return cv2.cvtColor(frame, cv2.COLOR_GRAY2RGB)
    return cv2.cvtColor(frame, cv2.COLOR_BGRA2RGB if frame.shape[2] == 4 else cv2.COLOR_BGR2RGB)


def _write_selection(candidates, n_read, fps, capture_root, name, origin, original, config, existing):
    records: list[ImageRecord] = []
    reports: list[FileReport] = []
    median = float(np.median([c.sharpness for c in candidates]))
    known = ThumbnailIndex.of_capture(existing, capture_root, config.near_duplicate_tolerance)
    ids = next_frame_ids(existing)
    for c in candidates:
        t = c.index / fps
        if c.sharpness < config.blur_ratio * median:
            reports.append(FileReport(name, False, f"blurry around {t:.2f} s: its sharpest frame has "
                                                   f"{c.sharpness / median:.0%} of the usual detail; no frame kept there"))
            continue
        thumb = thumbnail(c.rgb)
        twin = known.find(thumb)
        if twin is not None:
            reports.append(FileReport(name, False, f"frame at {t:.2f} s is nearly identical to {twin} (camera not moving?)"))
            continue
        frame_id = next(ids)
        data = encode_jpeg(c.rgb, config.jpeg_quality)
        image = Path("images") / f"{frame_id}.jpg"
        try:
            atomic_write_bytes(capture_root / image, data)
        except OSError as err:
            raise LirmUserError(f"{capture_root}: cannot write into the capture folder ({err}); "
                                "check free disk space and permissions") from err
        record = ImageRecord(frame_id=frame_id, original=original if original is not None else image, image=image,
                             width=c.rgb.shape[1], height=c.rgb.shape[0], sha256=hashlib.sha256(data).hexdigest(),
                             origin=origin, timestamp_s=t)
        records.append(record)
        known.add(thumb, describe(record))
        reports.append(FileReport(name, True, f"frame at {t:.2f} s", frame_id))
    return records, reports
