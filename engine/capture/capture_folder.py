"""A capture is a folder. The user's originals are copied into originals/ or referenced, never changed.

  CAPTURE/
    capture.json      frames (ids, files, hashes, pose and mask status), settings, normalisation,
                      updates (which views went into which LIRM update) and a history of actions
    transforms.json   nerfstudio-compatible cameras in the normalised world (OpenGL camera-to-world)
    originals/        byte-for-byte copies of the user's files (when copying)
    images/           working copies: EXIF orientation applied, long side capped
    masks/<id>.png    object masks (255 = object)
    prepared/<id>.npz the cropped network inputs (a cache: delete it and it is rebuilt)
    colmap/           the structure-from-motion workspace
    points.npy        sparse points in the normalised world
    observations.npz  per frame, the indices of the points that photo observed
    reconstruction/   LIRM updates: states and renders per update (lirm reconstruct)

Every write is atomic, and capture.json is rewritten after each stage, so a capture interrupted at
any point reopens at its last completed stage.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write, atomic_write_json
from lirm.engine.io.images import write_png

from .crop import PreparedView
from .history_journal import finish_commit
from .normalize import Normalization
from .records import FileReport, ImageRecord

CAPTURE_FILE = "capture.json"
FORMAT_VERSION = 1


@dataclass
class FrameState:
    record: ImageRecord
    pose_status: str = "not posed"  # "registered" or why not
    mask_status: str = "no mask"  # "ok" or what is wrong with it
    mask_source: str | None = None  # alpha | user | auto | fixed
    update: int | None = None  # the LIRM update that consumed this view
    pinhole_image: Path | None = None  # undistorted copy (relative), when the pose has lens distortion
    mask_warning: str | None = None  # a usable mask that may be wrong (e.g. cut by the image border)


@dataclass
class Capture:
    root: Path
    frames: dict[str, FrameState] = field(default_factory=dict)
    cameras: dict[str, Camera] = field(default_factory=dict)  # normalised world, registered frames
    normalization: Normalization | None = None
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # sparse points, normalised world
    # Which sparse points each frame observed (indices into `points`; from COLMAP's tracks): a point
    # a photo observed is visible in it, which the automatic masks use.
    observations: dict[str, np.ndarray] = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    reports: list[FileReport] = field(default_factory=list)
    updates: list[dict] = field(default_factory=list)
    history: list[dict] = field(default_factory=list)

    # ---- paths ------------------------------------------------------------------------------------
    def image_path(self, frame_id: str, pinhole: bool = True) -> Path:
        """The working image; with pinhole=True its undistorted copy where one exists (what the
        cameras in `cameras` describe)."""
        state = self.frames[frame_id]
        if pinhole and state.pinhole_image is not None:
            return self.root / state.pinhole_image
        return self.root / state.record.image

    def mask_path(self, frame_id: str) -> Path:
        return self.root / "masks" / f"{frame_id}.png"

    def prepared_path(self, frame_id: str) -> Path:
        return self.root / "prepared" / f"{frame_id}.npz"

    @property
    def records(self) -> list[ImageRecord]:
        return [self.frames[k].record for k in sorted(self.frames)]

    # ---- reading and writing pieces -----------------------------------------------------------------
    def read_image(self, frame_id: str, pinhole: bool = True) -> np.ndarray:
        """RGB(A) uint8 working image (see image_path)."""
        path = self.image_path(frame_id, pinhole)
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise LirmUserError(f"{path}: the capture's working image cannot be read; re-run `lirm capture --add` with the original")
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
        elif image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA)
        else:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
        return image

    def write_mask(self, frame_id: str, mask: np.ndarray, source: str, status: str) -> None:
        write_png(self.mask_path(frame_id), np.asarray(mask, np.uint8))
        self.frames[frame_id].mask_source = source
        self.frames[frame_id].mask_status = status

    def read_mask(self, frame_id: str) -> np.ndarray | None:
        path = self.mask_path(frame_id)
        return cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.exists() else None

    def write_prepared(self, view: PreparedView) -> None:
        def write(tmp: Path) -> None:
            with open(tmp, "wb") as f:
                np.savez_compressed(
                    f, image_masked=view.image_masked, image_bg=view.image_bg, mask=view.mask, plucker=view.plucker,
                    crop_box=np.array(view.crop_box), camera=np.array(json.dumps(view.camera.to_dict())),
                )

        atomic_write(self.prepared_path(view.frame_id), write)

    def read_prepared(self, frame_id: str) -> PreparedView | None:
        path = self.prepared_path(frame_id)
        if not path.exists():
            return None
        import zipfile
        import zlib

        try:
            with np.load(path) as data:
                camera = Camera.from_dict(json.loads(str(data["camera"])))
                return PreparedView(frame_id, data["image_masked"], data["image_bg"], data["mask"], data["plucker"],
                                    camera, tuple(int(v) for v in data["crop_box"]))
        except (zipfile.BadZipFile, zlib.error, OSError, ValueError, KeyError, EOFError, TypeError) as err:
            raise LirmUserError(f"the prepared view {path} is truncated or damaged ({type(err).__name__}: {err}); "
                                f"run `lirm capture --check {self.root}` to cut it again from its working image "
                                f"(or delete it to go on without this view)") from None

    def log(self, action: str, **details) -> None:
        self.history.append({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "action": action, **details})

    # ---- the whole capture --------------------------------------------------------------------------
    def save(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        atomic_write(self.root / "points.npy", self._write_points)
        atomic_write(self.root / "observations.npz", self._write_observations)
        atomic_write_json(self.root / CAPTURE_FILE, {
            "format": "lirm-capture",
            "version": FORMAT_VERSION,
            "settings": self.settings,
            "frames": [
                {**_record_dict(state.record), "pose_status": state.pose_status, "mask_status": state.mask_status,
                 "mask_source": state.mask_source, "mask_warning": state.mask_warning, "update": state.update,
                 "pinhole_image": None if state.pinhole_image is None else state.pinhole_image.as_posix()}
                for _, state in sorted(self.frames.items())
            ],
            "cameras": {k: self.cameras[k].to_dict() for k in sorted(self.cameras)},
            "normalization": None if self.normalization is None else self.normalization.to_dict(),
            "reports": [{"path": str(r.path), "accepted": r.accepted, "reason": r.reason, "frame_id": r.frame_id} for r in self.reports],
            "updates": self.updates,
            "history": self.history,
        })
        self._write_transforms()

    def _write_observations(self, tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **{k: np.asarray(v, dtype=np.int64) for k, v in self.observations.items()})

    def _write_points(self, tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.save(f, self.points)

    def _write_transforms(self) -> None:
        frames = []
        for frame_id in sorted(self.cameras):
            entry = {"file_path": self.image_path(frame_id).relative_to(self.root).as_posix(), **self.cameras[frame_id].to_dict(),
                     "lirm_frame_id": frame_id}
            if self.mask_path(frame_id).exists():
                entry["mask_path"] = f"masks/{frame_id}.png"
            frames.append(entry)
        applied = None if self.normalization is None else self.normalization.world_from_source[:3].tolist()
        atomic_write_json(self.root / "transforms.json", {
            "camera_model": "OPENCV",
            "frames": frames,
            # nerfstudio's name for a transform already applied to the poses (3x4, source -> these poses)
            "applied_transform": applied,
            "lirm": {"world": "object at the origin inside radius R, +Z up; transform_matrix is OpenGL camera-to-world"},
        })

    @classmethod
    def create(cls, root: str | Path, settings: dict | None = None) -> "Capture":
        root = Path(root)
        if root.exists() and any(root.iterdir()) and not _only_leftovers_of_a_killed_create(root):
            if (root / CAPTURE_FILE).exists():
                if not _finished(root / CAPTURE_FILE):
                    raise LirmUserError(f"{root} holds a capture that was interrupted before it was finished; finish it "
                                        f"with `lirm capture --resume {root}` (or choose a new folder)")
                raise LirmUserError(f"{root} already holds a capture; add photos with `lirm capture --add PHOTOS {root}`")
            raise LirmUserError(f"{root} exists and is not empty; choose a new folder for the capture")
        capture = cls(root=root, settings=dict(settings or {}))
        capture.log("created")
        capture.save()
        return capture

    @classmethod
    def open(cls, root: str | Path) -> "Capture":
        root = Path(root)
        path = root / CAPTURE_FILE
        if not path.exists():
            raise LirmUserError(f"{root} is not a capture (no {CAPTURE_FILE}); create one with `lirm capture PHOTOS -o {root}`")
        try:
            finish_commit(root)  # a change of the reconstruction history that a killed run left half done
        except OSError as exc:
            raise LirmUserError(f"{root}: an interrupted change of the reconstruction history could not be finished "
                                f"({exc}); make the folder writable and open it again") from None
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise LirmUserError(f"{path} cannot be read ({exc}); the capture folder is damaged") from None
        if data.get("format") != "lirm-capture" or int(data.get("version", 0)) > FORMAT_VERSION:
            raise LirmUserError(f"{path} is not a capture this version of LIRM Studio can read (version {data.get('version')})")
        capture = cls(root=root, settings=data.get("settings", {}), updates=data.get("updates", []), history=data.get("history", []))
        for f in data.get("frames", []):
            record = ImageRecord(
                frame_id=f["frame_id"], original=Path(f["original"]), image=Path(f["image"]), width=f["width"],
                height=f["height"], sha256=f["sha256"], has_alpha=f.get("has_alpha", False), origin=f.get("origin", "photo"),
                timestamp_s=f.get("timestamp_s"), focal_prior_px=f.get("focal_prior_px"),
                exposure_stops=f.get("exposure_stops"),
            )
            pinhole = f.get("pinhole_image")
            capture.frames[record.frame_id] = FrameState(record, f.get("pose_status", "not posed"), f.get("mask_status", "no mask"),
                                                         f.get("mask_source"), f.get("update"), Path(pinhole) if pinhole else None,
                                                         f.get("mask_warning"))
        capture.cameras = {k: Camera.from_dict(v) for k, v in data.get("cameras", {}).items()}
        if data.get("normalization"):
            capture.normalization = Normalization.from_dict(data["normalization"])
        capture.reports = [FileReport(Path(r["path"]), r["accepted"], r.get("reason", ""), r.get("frame_id")) for r in data.get("reports", [])]
        points = root / "points.npy"
        if points.exists():
            capture.points = np.load(points)
        observations = root / "observations.npz"
        if observations.exists():
            with np.load(observations) as data:
                capture.observations = {k: data[k] for k in data.files}
        return capture


def _only_leftovers_of_a_killed_create(root: Path) -> bool:
    """A folder holding only what `create` writes before capture.json exists (a run killed in its
    first moments): starting again there loses nothing."""
    ours = {"points.npy", "observations.npz", "transforms.json", ".lock"}
    return not (root / CAPTURE_FILE).exists() and all(
        p.is_file() and (p.name in ours or ".tmp" in p.name) for p in root.iterdir())


def _finished(capture_file: Path) -> bool:
    """Whether a capture ran its last stage (crops) or stopped for a reason it recorded."""
    try:
        data = json.loads(capture_file.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return True  # unreadable: not something --resume could finish; the "already holds" message stands
    settings = data.get("settings", {})
    stopped = any(h.get("action") == "stopped" for h in data.get("history", []))
    return "crops" in settings.get("completed", []) or stopped


def _record_dict(record: ImageRecord) -> dict:
    d = asdict(record)
    d["original"] = str(record.original)
    d["image"] = record.image.as_posix()
    return d
