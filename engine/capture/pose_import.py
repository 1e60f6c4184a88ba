"""Import camera poses made elsewhere: transforms.json (NeRF/Blender, instant-ngp, nerfstudio) or a
COLMAP sparse model folder. Frames are matched to the capture's images by the original file's name.

Intrinsics in a file are for the resolution the file describes (w, h; else the original image's own
size); they are rescaled to the working copy's size, so the cameras fit the capture's images.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import Any, Mapping, Sequence

from lirm.engine.cameras import Camera
from lirm.engine.capture.colmap_posing import STATUS_REGISTERED, reconstruction_to_posing
from lirm.engine.capture.records import ImageRecord, PosingResult
from lirm.engine.errors import LirmUserError

__all__ = ["import_transforms_json", "import_colmap_model", "STATUS_NO_POSE_JSON", "STATUS_NO_POSE_MODEL"]

STATUS_NO_POSE_JSON = "no pose in transforms.json"
STATUS_NO_POSE_MODEL = "no pose in the COLMAP model"

# Keys that belong to one camera; everything else at the top level (aabb_scale, scale, offset,
# applied_transform, ply_file_path, ...) does not change the cameras and is ignored.
_CAMERA_KEYS = ("camera_model", "w", "h", "fl_x", "fl_y", "cx", "cy", "camera_angle_x", "camera_angle_y",
                "k1", "k2", "k3", "k4", "k5", "k6", "p1", "p2")


class _Matcher:
    """Find the ImageRecord for a file name from a pose file: exact name first, then the name
    without extension (NeRF file_path entries often have none, or a converted file's)."""

    def __init__(self, images: Sequence[ImageRecord]):
        self.by_name: dict[str, ImageRecord] = {}
        self.by_stem: dict[str, ImageRecord] = {}
        for rec in images:
            name = Path(rec.original).name
            self.by_name.setdefault(name, rec)
            self.by_name.setdefault(name.lower(), rec)
            stem = Path(name).stem
            self.by_stem.setdefault(stem, rec)
            self.by_stem.setdefault(stem.lower(), rec)

    def find(self, file_path: str) -> ImageRecord | None:
        # Windows separators appear in files written on Windows; either way only the name matters.
        name = PureWindowsPath(str(file_path)).name if "\\" in str(file_path) else PurePosixPath(str(file_path)).name
        for key in (name, name.lower()):
            if key in self.by_name:
                return self.by_name[key]
        for key in (name, name.lower(), Path(name).stem, Path(name).stem.lower()):
            if key in self.by_stem:
                return self.by_stem[key]
        return None


def _image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) of an image file as displayed (EXIF orientation applied), or None."""
    try:
        from PIL import Image
    except ImportError:  # pragma: no cover - Pillow is a dependency
        return None
    try:
        with Image.open(path) as im:
            w, h = im.size
            orientation = im.getexif().get(0x0112, 1)
    except (OSError, ValueError):
        return None
    # Orientations 5-8 swap the axes; the working copy has EXIF orientation applied.
    return (h, w) if orientation in (5, 6, 7, 8) else (w, h)


def _file_size_for(rec: ImageRecord, d: Mapping[str, Any]) -> tuple[int, int]:
    """The resolution the file's intrinsics refer to: its w, h, else the original image's size."""
    if "w" in d and "h" in d:
        return int(round(float(d["w"]))), int(round(float(d["h"])))
    size = _image_size(Path(rec.original))
    if size is not None:
        w, h = size
        if "w" in d:
            w = int(round(float(d["w"])))
            h = round(w * size[1] / size[0])
        elif "h" in d:
            h = int(round(float(d["h"])))
            w = round(h * size[0] / size[1])
        return w, h
    # No size anywhere: the working copy's. Exact for a field of view (camera_angle_x) and a
    # centred principal point, the usual case of files without w/h.
    return rec.width, rec.height


def import_transforms_json(path: str | os.PathLike, images: list[ImageRecord]) -> PosingResult:
    """Cameras from a transforms.json (NeRF/Blender, instant-ngp or nerfstudio), by original file name.

    Poses are OpenGL camera-to-world (converted to OpenCV); intrinsics come from the frame or the
    top level (fl_x/fl_y/cx/cy/k1/k2/p1/p2, or camera_angle_x), for the resolution w x h of the
    file (else the original image's size), and are rescaled to each working copy's size. Frames
    without a matching image are ignored; images without a frame get STATUS_NO_POSE_JSON.
    Unreadable or malformed files raise LirmUserError naming the file and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise LirmUserError(f"{path}: file not found (expected a transforms.json with camera poses)")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as e:
        raise LirmUserError(f"{path}: cannot read the file ({e})") from e
    except json.JSONDecodeError as e:
        raise LirmUserError(f"{path}: not valid JSON (line {e.lineno}: {e.msg})") from e
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list):
        raise LirmUserError(f"{path}: no 'frames' list; this is not a NeRF / instant-ngp / nerfstudio transforms.json")
    top = {k: data[k] for k in _CAMERA_KEYS if k in data}
    matcher = _Matcher(images)
    cameras: dict[str, Camera] = {}
    for k, frame in enumerate(data["frames"]):
        if not isinstance(frame, dict) or "file_path" not in frame:
            raise LirmUserError(f"{path}: frame {k} has no 'file_path'")
        rec = matcher.find(frame["file_path"])
        if rec is None or rec.frame_id in cameras:
            continue
        d = {**top, **{key: frame[key] for key in frame if key in _CAMERA_KEYS or key == "transform_matrix"}}
        where = f"{path}: frame {k} ({frame['file_path']})"
        if "transform_matrix" not in d:
            raise LirmUserError(f"{where} has no 'transform_matrix'")
        vertical_only = "fl_x" not in d and "camera_angle_x" not in d
        if vertical_only and "fl_y" not in d and "camera_angle_y" not in d:
            raise LirmUserError(f"{where}: no focal length (needs fl_x or camera_angle_x)")
        try:
            w, h = _file_size_for(rec, d)
            d["w"], d["h"] = w, h
            if vertical_only:  # instant-ngp accepts a vertical focal length or FoV alone
                d["fl_x"] = d["fl_y"] if "fl_y" in d else 0.5 * h / math.tan(0.5 * float(d["camera_angle_y"]))
            cam = Camera.from_dict(d)
        except (ValueError, TypeError) as e:
            raise LirmUserError(f"{where}: {e}") from e
        if (cam.width, cam.height) != (rec.width, rec.height):
            cam = cam.resized(rec.width, rec.height)
        cameras[rec.frame_id] = cam
    status = {rec.frame_id: STATUS_REGISTERED if rec.frame_id in cameras else STATUS_NO_POSE_JSON for rec in images}
    return PosingResult(cameras=cameras, status=status, source="transforms.json")


def import_colmap_model(path: str | os.PathLike, images: list[ImageRecord]) -> PosingResult:
    """Cameras and sparse points of a COLMAP sparse model folder (cameras, images, points3D as .bin
    or .txt), matched to the images by name (COLMAP image name vs the original file name).

    Intrinsics are rescaled from the model's camera size to each working copy's size. Images the
    model lacks get STATUS_NO_POSE_MODEL. Missing or malformed files, or unsupported (fisheye)
    camera models, raise LirmUserError.
    """
    path = Path(path)
    if not path.is_dir():
        raise LirmUserError(f"{path}: not a folder; give the COLMAP sparse model folder (e.g. sparse/0)")
    missing = [n for n in ("cameras", "images", "points3D")
               if not (path / f"{n}.bin").is_file() and not (path / f"{n}.txt").is_file()]
    if missing:
        sub = [p for p in sorted(path.glob("*/cameras.*")) if p.suffix in (".bin", ".txt")]
        hint = f" (did you mean {sub[0].parent}?)" if sub else ""
        raise LirmUserError(
            f"{path}: not a COLMAP model, missing {', '.join(m + '.bin/.txt' for m in missing)}{hint}"
        )
    try:
        import pycolmap
    except ImportError as e:
        raise LirmUserError(f"pycolmap is not installed or failed to load ({e}); reinstall the project") from e
    try:
        rec = pycolmap.Reconstruction(str(path))
    except (ValueError, RuntimeError, OSError) as e:
        raise LirmUserError(f"{path}: cannot read the COLMAP model ({e})") from e
    matcher = _Matcher(images)
    frame_of: dict[str, str] = {}
    for image_id in rec.reg_image_ids():
        name = rec.images[image_id].name
        found = matcher.find(name)
        if found is not None:
            frame_of[name] = found.frame_id
    sizes = {r.frame_id: (r.width, r.height) for r in images}
    try:
        result = reconstruction_to_posing(rec, frame_of.get, sizes, source="colmap-model")
    except ValueError as e:
        raise LirmUserError(f"{path}: {e}") from e
    result.status = {r.frame_id: STATUS_REGISTERED if r.frame_id in result.cameras else STATUS_NO_POSE_MODEL
                     for r in images}
    return result

