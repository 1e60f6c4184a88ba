"""Frames from video: sharp, spread over time, no still-camera repeats; cameras go through the same loop."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from lirm.engine.capture.ingest import Cancelled
from lirm.engine.capture.records import ImageRecord
from lirm.engine.capture.video_frames import VideoConfig, select_stream_frames, select_video_frames
from lirm.engine.errors import LirmUserError

FPS, N = 30, 90
ISOLATED_BLUR = {3, 7, 20, 52, 77}


def _texture() -> np.ndarray:
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.integers(0, 256, (240, 1000, 3)).astype(np.uint8), (0, 0), 1.5)
    for _ in range(40):
        centre = (int(rng.integers(0, 1000)), int(rng.integers(0, 240)))
        cv2.circle(tex, centre, int(rng.integers(5, 30)), tuple(int(v) for v in rng.integers(0, 256, 3)), -1)
    return tex


def _write_video(path: Path, blurred: set[int], still_from: int | None = None) -> Path:
    """A camera panning over a texture (4 px a frame), optionally stopping at `still_from`."""
    tex = _texture()
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (320, 240))
    assert writer.isOpened()
    for i in range(N):
        x = 4 * (i if still_from is None else min(i, still_from))
        frame = tex[:, x:x + 320].copy()
        writer.write(cv2.GaussianBlur(frame, (0, 0), 3) if i in blurred else frame)
    writer.release()
    return path


def _index(record: ImageRecord) -> int:
    return round(record.timestamp_s * FPS)


class _NoLength:
    """A video file posing as a live stream: same frames, but no frame count (like a camera)."""

    def __init__(self, path: Path):
        self.capture = cv2.VideoCapture(str(path))

    def read(self):
        return self.capture.read()

    def get(self, prop_id: int) -> float:
        return -1.0 if prop_id == cv2.CAP_PROP_FRAME_COUNT else self.capture.get(prop_id)


@pytest.fixture(scope="module")
def panning_video(tmp_path_factory) -> Path:
    return _write_video(tmp_path_factory.mktemp("video") / "pan.avi", ISOLATED_BLUR)


def test_one_sharp_frame_per_time_bin(panning_video, tmp_path):
    calls = []
    records, reports = select_video_frames(panning_video, tmp_path, VideoConfig(target_frames=6),
                                           progress=lambda done, total: calls.append((done, total)))
    assert [r.frame_id for r in records] == ["0001", "0002", "0003", "0004", "0005", "0006"]
    assert [_index(r) // 15 for r in records] == [0, 1, 2, 3, 4, 5]  # exact 15-frame bins
    assert not {_index(r) for r in records} & ISOLATED_BLUR
    assert all(r.accepted for r in reports) and len(reports) == 6
    for r in records:
        assert r.origin == "video" and r.original == panning_video.resolve() and (r.width, r.height) == (320, 240)
        assert cv2.imread(str(tmp_path / r.image)).shape == (240, 320, 3)
    assert calls[-1] == (N, N)


def test_blurry_stretch_and_still_camera_are_dropped(tmp_path):
    video = _write_video(tmp_path / "shaky.avi", set(range(30, 48)) | {7}, still_from=60)
    records, reports = select_video_frames(video, tmp_path / "cap", VideoConfig(target_frames=6))
    # Bins 0..5 are frames [0,15), [15,30), ...: bin 2 is all blur, bins 4 and 5 see the same view.
    assert [_index(r) // 15 for r in records] == [0, 1, 3, 4]
    assert not {_index(r) for r in records} & (set(range(30, 48)) | {7})
    skipped = [r.reason for r in reports if not r.accepted]
    assert len(skipped) == 2
    assert skipped[0].startswith("blurry around 1.") and "camera not moving" in skipped[1]
    assert all(r.path == video for r in reports)


def test_a_stream_without_frame_count_goes_through_the_same_loop(panning_video, tmp_path):
    config = VideoConfig(target_frames=6, max_seconds=1.5)  # a camera is read for max_seconds
    records, reports = select_stream_frames(_NoLength(panning_video), tmp_path, name=Path("camera 0"),
                                            origin="camera", original=None, config=config)
    indices = [_index(r) for r in records]
    assert len(records) == 6 and indices == sorted(indices) and max(indices) < 45
    # Bins are regrouped from coarser fine bins, so each pick lies within a bin of its ideal place.
    assert all(abs(i - (7.5 * j + 3.75)) <= 7.5 for j, i in enumerate(indices))
    assert not set(indices) & ISOLATED_BLUR
    for r in records:
        assert r.origin == "camera" and r.original == r.image  # the working copy is the only copy

    frames_seen = []
    stopped, _ = select_stream_frames(_NoLength(panning_video), tmp_path / "s", name=Path("camera 0"), origin="camera",
                                      original=None, config=VideoConfig(target_frames=6),
                                      progress=lambda done, total: frames_seen.append(done),
                                      stop=lambda: len(frames_seen) >= 45)  # the user presses Stop
    assert [_index(r) for r in stopped] == indices  # same frames as reading 1.5 s

    long_config = VideoConfig(target_frames=6, max_seconds=60)  # the stream ends first
    records, _ = select_stream_frames(_NoLength(panning_video), tmp_path / "b", name=Path("camera 0"),
                                      origin="camera", original=None, config=long_config)
    indices = [_index(r) for r in records]
    assert len(records) == 6 and indices[0] < 16 and indices[-1] >= 64
    assert all(abs(i - (15 * j + 7.5)) <= 15 for j, i in enumerate(indices))


def test_ids_continue_and_the_same_video_twice_adds_nothing(panning_video, tmp_path):
    earlier = ImageRecord("0007", Path("originals/x.jpg"), Path("images/0007.jpg"), 10, 10, "0" * 64)
    first, _ = select_video_frames(panning_video, tmp_path, VideoConfig(target_frames=3), existing=[earlier])
    assert [r.frame_id for r in first] == ["0008", "0009", "0010"]
    again, reports = select_video_frames(panning_video, tmp_path, VideoConfig(target_frames=3), existing=[earlier, *first])
    assert again == [] and all("nearly identical to frame 00" in r.reason for r in reports)


def test_unreadable_sources_name_themselves(tmp_path, panning_video):
    with pytest.raises(LirmUserError, match="missing.mp4"):
        select_video_frames(tmp_path / "missing.mp4", tmp_path / "cap")
    broken = tmp_path / "broken.mp4"
    broken.write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(range(256)) * 40)
    with pytest.raises(LirmUserError, match="broken.mp4"):
        select_video_frames(broken, tmp_path / "cap")
    with pytest.raises(Cancelled):
        select_video_frames(panning_video, tmp_path / "cap", cancel=lambda: True)
    assert not (tmp_path / "cap").exists()  # nothing is written before the whole stream is read


def _tag_as_turned_clockwise(path: Path) -> None:
    """Set the MP4 track header's display matrix to a quarter turn clockwise, as a phone held upright
    writes its landscape sensor's frames (ISO/IEC 14496-12 tkhd, version 0: the matrix 36 bytes in)."""
    data = bytearray(path.read_bytes())
    box = data.find(b"tkhd") - 4
    assert box >= 0 and data[box + 8] == 0, "a version-0 track header"
    matrix = box + 8 + 4 + 20 + 8 + 8  # header, version/flags, times/track/duration, reserved, layer..volume
    assert struct.unpack(">9i", data[matrix:matrix + 36]) == (65536, 0, 0, 0, 65536, 0, 0, 0, 1 << 30)
    struct.pack_into(">9i", data, matrix, 0, 65536, 0, -65536, 0, 0, 0, 0, 1 << 30)
    path.write_bytes(bytes(data))


def test_a_phones_upright_video_gives_upright_frames(tmp_path):
    """Phones store portrait video as landscape frames with a rotation in the file: the frames must come
    out turned, or the capture's world would lie on its side (its up is the cameras' average up)."""
    path = tmp_path / "portrait.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), FPS, (320, 240))
    assert writer.isOpened()
    tex = _texture()
    stored = [tex[:, 4 * i:4 * i + 320].copy() for i in range(N)]
    for frame in stored:
        writer.write(frame)
    writer.release()
    _tag_as_turned_clockwise(path)
    records, _ = select_video_frames(path, tmp_path / "capture")
    assert records and all((r.width, r.height) == (240, 320) for r in records)
    first = cv2.imread(str(tmp_path / "capture" / records[0].image))
    upright = np.rot90(stored[_index(records[0])], k=-1)
    assert np.abs(first.astype(float) - upright).mean() < 12  # two lossy encodings of the same picture
    assert np.abs(first.astype(float) - np.rot90(stored[_index(records[0])], k=1)).mean() > 30
