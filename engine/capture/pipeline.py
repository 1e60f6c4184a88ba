"""The capture pipeline: ingest -> pose -> undistort -> normalise -> mask -> crop, with progress,
cancel and resumption. `lirm capture`, the demo and (later) the app all call these functions.

Each stage records its result in the capture folder before the next starts, so an interrupted run
reopens where it stopped (`resume_capture`). Frames keep their ids through every stage and through
`add_to_capture`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.images import write_png

from .auto_mask import AutoMaskConfig, automatic_masks
from .plain_backdrop import BACKDROP, PlainBackdropConfig, plain_backdrop_capture
from .pose_silhouettes import PoseSilhouetteConfig, views_against_silhouettes
from .capture_folder import Capture, FrameState
from .colmap_posing import ColmapConfig, extend_colmap_pose, map_again_without, pose_with_colmap
from .focal_check import pose_again_if_focal_is_off
from .crop import CropConfig, EmptyMaskError, prepare_view
from .exposure_estimate import estimate_exposure_stops
from .exposure_match import (ESTIMATED_EXPOSURE_KEY, capture_exposure_gains, capture_response, estimate_record,
                             exposure_matched_image, match_exposure, matching_gains)
from ..lighting.camera_response import RESPONSES, response_for_capture
from ..lighting.capture_lighting import CaptureLightingConfig, estimate_capture_lighting
from .disk_space import require_free_space, stage_bytes
from .ingest import Cancelled, IngestConfig, ingest_photos, natural_key
from .masks import check_mask, cut_by_border, load_user_masks, mask_from_alpha, propagate_mask_fix
from .fit_to_silhouettes import fit_world_to_silhouettes, moved_camera, moved_normalization, size_world_from_silhouettes
from .imported_pose_points import points_in_imported_frame
from .normalize import NormalizeConfig, estimate_normalization, is_floor
from .pose_import import import_colmap_model, import_transforms_json
from .records import PosingResult
from .undistort import undistort_image
from .photo_formats import FORMATS_IN_WORDS, VIDEO_SUFFIXES, folders_with_photos
from .video_frames import VideoConfig, select_video_frames

STAGES = ("ingest", "pose", "normalize", "masks", "crops")
STAGE_WORDS = {"pose": "pose the photos (COLMAP)", "masks": "write the masks", "crops": "prepare the network's crops",
               "lighting": "estimate the lighting the photos were taken in"}

log = logging.getLogger(__name__)

Progress = Callable[[str, int, int], None]  # (stage, done, total)


@dataclass
class CaptureConfig:
    ingest: IngestConfig = field(default_factory=IngestConfig)
    video: VideoConfig = field(default_factory=VideoConfig)
    colmap: ColmapConfig = field(default_factory=ColmapConfig)
    normalize: NormalizeConfig = field(default_factory=NormalizeConfig)
    auto_mask: AutoMaskConfig = field(default_factory=AutoMaskConfig)
    backdrop: PlainBackdropConfig = field(default_factory=PlainBackdropConfig)
    pose_silhouettes: PoseSilhouetteConfig = field(default_factory=PoseSilhouetteConfig)
    crop: CropConfig = field(default_factory=CropConfig)
    lighting: CaptureLightingConfig = field(default_factory=CaptureLightingConfig)
    masks: str = "auto"  # auto (alpha where every image has it, else automatic) | alpha | automatic | a folder
    # The photos' tone curve: auto (camera_response.response_for_capture) | aces | srgb
    camera_response: str = "auto"
    poses: str | None = None  # a transforms.json or COLMAP model folder to use instead of structure from motion


@dataclass
class CaptureSummary:
    capture: Capture
    accepted: int
    skipped: int
    registered: int
    masked: int
    prepared: int
    nothing_new: bool = False  # `--add` where every photo was skipped: no stage ran

    @property
    def usable(self) -> bool:
        return self.registered > 0

    @property
    def reconstructable(self) -> bool:
        """Posed and with at least one prepared view (what `lirm reconstruct` needs)."""
        return self.registered > 0 and self.prepared > 0


def run_capture(inputs: str | Path | int, out: str | Path, config: CaptureConfig = CaptureConfig(),
                progress: Progress | None = None, cancel: Callable[[], bool] | None = None) -> CaptureSummary:
    """Create a capture from a folder of photos, a video file or a camera index.

    Nothing is left behind when there is no input to make a capture of (a missing folder, no photo
    in it, a video that does not decode, a camera that does not open): the folder is removed again
    (or emptied, if it existed empty), so that the retry starts clean."""
    out = Path(out)
    _check_input_exists(inputs, out)
    existed = out.exists()
    capture = Capture.create(out, settings=_settings(config))
    capture.settings["inputs"] = str(inputs)
    try:
        _ingest(capture, inputs, config, progress, cancel)
        if not capture.frames:
            raise LirmUserError(_no_photos_message(inputs, capture.reports))
    except (LirmUserError, Cancelled):
        if not capture.frames:
            _remove_new_capture(out, existed)
        raise
    return _finish(capture, config, progress, cancel, new_frames=None)


def _check_input_exists(inputs, out: Path) -> None:
    if isinstance(inputs, int):
        return
    path = Path(inputs)
    if not path.exists():
        raise LirmUserError(f"{path}: no such folder, photo or video; check the path (nothing was created)")
    try:
        inside = out.resolve().is_relative_to(path.resolve()) and path.is_dir()
    except OSError:
        inside = False
    if inside:
        raise LirmUserError(f"-o {out} is inside the photo folder {path}: its images would be imported as photos "
                            f"next time; choose a capture folder outside it")


def _no_photos_message(inputs, reports) -> str:
    files = [r for r in reports if r.path.is_file()]
    # Photos one level or more down (a phone's DCIM/100APPLE, an export by date) are not taken in
    # silently: subfolders may hold other objects. They are named, so the user can point at one.
    inside = folders_with_photos(Path(inputs)) if isinstance(inputs, (str, Path)) and Path(inputs).is_dir() else []
    if inside:
        named = ", ".join(f"{folder.relative_to(inputs)} ({count})" for folder, count in inside[:4])
        more = f" and {len(inside) - 4} more" if len(inside) > 4 else ""
        first = inside[0][0]
        return (f"{inputs}: no photos directly in it; its subfolders hold photos: {named}{more}. A capture takes "
                f"the photos of one folder (one object): point at the folder itself, for example {first}")
    if not files:
        return (f"{inputs}: no photos found (the folder holds no files); put the photos ({FORMATS_IN_WORDS}) "
                f"directly in it, or name a video or camera:N")
    reasons = "; ".join(f"{r.path.name}: {r.reason}" for r in files[:3])
    more = f" (and {len(files) - 3} more)" if len(files) > 3 else ""
    return f"{inputs}: none of its {len(files)} files is a usable photo ({reasons}{more})"


def _remove_new_capture(out: Path, existed: bool) -> None:
    import shutil

    if not existed:
        shutil.rmtree(out, ignore_errors=True)
        return
    for entry in out.iterdir():  # it was empty before this run: only what this run wrote is there
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)


def resume_capture(root: str | Path, config: CaptureConfig = CaptureConfig(), progress: Progress | None = None,
                   cancel: Callable[[], bool] | None = None) -> CaptureSummary:
    """Run whatever stages an interrupted capture had not finished."""
    capture = Capture.open(root)
    return _finish(capture, config, progress, cancel, new_frames=None)


def add_to_capture(root: str | Path, inputs: str | Path | int, config: CaptureConfig = CaptureConfig(),
                   progress: Progress | None = None, cancel: Callable[[], bool] | None = None) -> CaptureSummary:
    """Ingest more photos into a capture and pose, mask and crop them; old frames keep their ids."""
    capture = Capture.open(root)
    before = set(capture.frames)
    _ingest(capture, inputs, config, progress, cancel)
    new = sorted(set(capture.frames) - before)
    if not new:
        capture.log("add", added=0)
        capture.save()
        summary = _summary(capture)
        summary.nothing_new = True
        return summary
    capture.settings.pop("completed", None)
    return _finish(capture, config, progress, cancel, new_frames=new)


def fix_mask(root: str | Path, frame_id: str, mask: np.ndarray, config: CaptureConfig = CaptureConfig()):
    """The user corrected one view's mask: see engine/capture/mask_fix.py (guards, backups, undo)."""
    from .mask_fix import fix_mask as fix

    return fix(root, frame_id, mask, radius=config.normalize.target_radius, crop=config.crop)


# ---- stages ---------------------------------------------------------------------------------------
def _ingest(capture: Capture, inputs, config: CaptureConfig, progress, cancel) -> None:
    start = time.perf_counter()
    existing = capture.records
    stage_progress = _stage(progress, "ingest")
    if isinstance(inputs, int) or Path(inputs).suffix.lower() in VIDEO_SUFFIXES:
        records, reports = select_video_frames(inputs, capture.root, config.video, existing=existing, progress=stage_progress, cancel=cancel)
    else:
        path = Path(inputs)
        if not path.exists():
            raise LirmUserError(f"{path}: no such folder, photo or video")
        candidates = [p for p in (path.iterdir() if path.is_dir() else [path]) if p.is_file()]
        require_free_space(capture.root, stage_bytes("ingest", len(candidates), config.ingest.max_side, config.crop.size,
                                                     sum(p.stat().st_size for p in candidates) if config.ingest.copy_originals else 0),
                           "import the photos")
        records, reports = ingest_photos(_photos_without_masks(path, config.masks), capture.root, config.ingest,
                                         existing=existing, progress=stage_progress, cancel=cancel)
    for record in records:
        capture.frames[record.frame_id] = FrameState(record)
    capture.reports.extend(reports)
    capture.log("ingest", inputs=str(inputs), accepted=len(records), skipped=sum(not r.accepted for r in reports))
    capture.settings.setdefault("timings", {})["ingest"] = round(time.perf_counter() - start, 3)
    capture.save()


def _photos_without_masks(path: Path, masks: str):
    """The photo folder, or its files without the mask folder's (`--masks FOLDER` inside or equal to
    the photo folder): masks are neither imported nor reported as skipped photos."""
    mask_folder = Path(masks) if masks not in ("auto", "alpha", "automatic") else None
    if mask_folder is None or not path.is_dir() or not mask_folder.is_dir():
        return path
    mask_folder = mask_folder.resolve()
    if mask_folder != path.resolve() and mask_folder.parent != path.resolve():
        return path
    mask_names = {p.name for p in mask_folder.iterdir()} if mask_folder == path.resolve() else set()
    return [p for p in sorted(path.iterdir(), key=natural_key)
            if p.resolve() != mask_folder and not (p.name in mask_names and _looks_like_mask_name(p.name))]


def _looks_like_mask_name(name: str) -> bool:
    return "mask" in name.lower()


def _finish(capture: Capture, config: CaptureConfig, progress, cancel, new_frames: list[str] | None) -> CaptureSummary:
    if not capture.frames:
        capture.save()
        return _summary(capture)
    completed = capture.settings.get("completed", [])
    if "pose" not in completed or new_frames:
        _timed(capture, config, "pose", lambda: _pose(capture, config, progress, cancel, new_frames))
    if not capture.cameras:
        capture.log("stopped", reason="no photo could be posed")
        capture.save()
        return _summary(capture)
    for stage, run in (("normalize", lambda: _normalize(capture, config)),
                       ("masks", lambda: _masks(capture, config, progress, cancel)),
                       # the lighting first: it decides the camera curve the crops are exposure-matched through
                       ("lighting", lambda: _lighting(capture, config, cancel)),
                       ("crops", lambda: _crops(capture, config, progress, cancel))):
        if stage not in capture.settings.get("completed", []) or new_frames:
            _timed(capture, config, stage, run)
    return _summary(capture)


def _timed(capture: Capture, config: CaptureConfig, stage: str, run: Callable[[], None]) -> None:
    """Run a stage (after checking the disk has room for what it writes), then record its wall time
    (capture.settings["timings"]) and mark it complete."""
    needed = stage_bytes(stage, len(capture.frames), config.ingest.max_side, config.crop.size)
    require_free_space(capture.root, needed, STAGE_WORDS.get(stage, stage))
    start = time.perf_counter()
    run()
    capture.settings.setdefault("timings", {})[stage] = round(time.perf_counter() - start, 3)
    _mark(capture, stage)


def _pose(capture: Capture, config: CaptureConfig, progress, cancel, new_frames) -> None:
    records = capture.records
    if config.poses:
        path = Path(config.poses)
        result = import_transforms_json(path, records) if path.is_file() else import_colmap_model(path, records)
        if len(result.points) == 0 and _mask_mode(config, all(r.has_alpha for r in records)) == "automatic":
            # The automatic masks are seeded by sparse points, which a transforms.json does not hold.
            colmap = pose_with_colmap(records, capture.root, capture.root / "colmap", config=config.colmap,
                                      progress=_substages(progress, "points"), cancel=cancel)
            result, note = points_in_imported_frame(result, colmap)
            capture.log("points for imported poses", note=note)
    else:
        work = capture.root / "colmap"
        pose_progress = _substages(progress, "pose")
        if new_frames and (work / "sparse").exists():
            new_records = [capture.frames[f].record for f in new_frames]
            result = extend_colmap_pose(work, new_records, capture.root, config=config.colmap, progress=pose_progress, cancel=cancel)
        else:
            result = pose_with_colmap(records, capture.root, work, config=config.colmap, progress=pose_progress, cancel=cancel)
            result, note = pose_again_if_focal_is_off(result, records, capture.root, work, config.colmap, pose_progress, cancel)
            if note:
                capture.log("focal length check", note=note)
    _apply_posing(capture, result)
    if new_frames:  # a new structure-from-motion frame: normalise again
        capture.settings["completed"] = [s for s in capture.settings.get("completed", []) if s == "pose"]
    capture.log("pose", source=result.source, registered=len(result.cameras), total=len(records))
    capture.save()


def _apply_posing(capture: Capture, result: PosingResult) -> None:
    capture.settings["pose_source"] = result.source
    raw = {}
    for frame_id, state in capture.frames.items():
        state.pose_status = result.status.get(frame_id, "not posed")
    for frame_id, camera in result.cameras.items():
        if frame_id in capture.frames:
            raw[frame_id] = camera
            capture.frames[frame_id].pose_status = "registered"
    capture.settings["source_cameras"] = {k: v.to_dict() for k, v in raw.items()}
    capture.cameras = raw  # source frame until normalised
    capture.points = np.asarray(result.points, dtype=np.float64).reshape(-1, 3)
    capture.observations = {f: np.asarray(v, dtype=np.int64) for f, v in result.observations.items() if f in capture.frames}


def _normalize(capture: Capture, config: CaptureConfig) -> None:
    from lirm.engine.cameras import Camera

    source = {k: Camera.from_dict(v) for k, v in capture.settings.get("source_cameras", {}).items()}
    # Every photo's (a view mapped again may register where it did not): the capture is on a plain
    # backdrop or not whichever of its photos COLMAP posed.
    backdrops = _plain_backdrop_maps(capture, config, list(capture.frames))
    capture.settings["plain_backdrop"] = backdrops is not None  # the masks stage goes by it
    outlines = _outlines_without_poses(capture, config, backdrops)
    normalize_config = config.normalize
    if backdrops is not None:
        # Nothing on a plain backdrop is a floor: the plane the points hold is the object's base.
        normalize_config = replace(normalize_config, find_plane=False)

    def world(source: dict):
        norm = estimate_normalization(source, capture.points if len(capture.points) else None, normalize_config)
        if backdrops is not None:
            # On a plain backdrop, what is not backdrop outlines the object in every photo before any
            # mask; its hull sizes the world, as the masks' hull does for imported poses. Without it
            # the lego's 50 views with their own poses (sized by the cameras alone until the masks'
            # hull did it) were masked at IoU 0.741, with it 0.977 (README, "Captures").
            norm = _size_by_outlines(norm, {f: o for f, o in outlines.items() if f in source}, source, config)
        return norm

    norm = world(source)
    # Again after each round: mapped and sized without the views left out, the hull judges the rest
    # better (the lego on white: 11 of its 14 wrong views in the first round, 2 more in the second).
    left_out_so_far: dict[str, float] = {}
    for _ in range(3):
        left_out = _views_against_outlines(capture, config, source, norm, outlines, sized=backdrops is not None,
                                           earlier=len(left_out_so_far))
        if not left_out:
            break
        left_out_so_far.update(left_out)
        source = _posed_without(capture, left_out_so_far, source)
        norm = world(source)
    capture.normalization = norm
    capture.cameras = {k: norm.apply_to_camera(c) for k, c in source.items()}
    capture.points = norm.apply_to_points(capture.points) if len(capture.points) else capture.points
    # Pinhole working images for every later stage (see undistort.py).
    for frame_id, camera in list(capture.cameras.items()):
        capture.frames[frame_id].pinhole_image = None
        if camera.distortion is not None:
            image, pinhole = undistort_image(capture.read_image(frame_id, pinhole=False), camera)
            rel = Path("undistorted") / f"{frame_id}.png"
            write_png(capture.root / rel, image)
            capture.frames[frame_id].pinhole_image = rel
            capture.cameras[frame_id] = pinhole
    capture.log("normalize", radius_source=norm.radius_source, used_points=norm.used_points)
    capture.save()


def _masks(capture: Capture, config: CaptureConfig, progress, cancel) -> None:
    posed = sorted(capture.cameras)
    images = {f: capture.read_image(f) for f in posed}
    mode = _mask_mode(config, all(images[f].shape[2] == 4 for f in posed))
    if mode == "alpha":
        missing = [f for f in posed if images[f].shape[2] != 4]
        if missing:
            raise LirmUserError(f"--masks alpha: {len(missing)} photos have no alpha channel (e.g. "
                                f"{capture.frames[missing[0]].record.original.name}); use --masks auto or a mask folder")
        masks = {f: mask_from_alpha(images[f]) for f in posed}
        source = "alpha"
    elif mode == "automatic":
        rgb = {f: images[f][:, :, :3] for f in posed}
        radius = config.normalize.target_radius
        search = _mask_search_radius(config)
        is_object = None
        mask_config = config.auto_mask
        plane = None if capture.normalization is None else capture.normalization.plane
        # Found again on the undistorted images the masks are made on, unless normalisation found the
        # capture not plain (older captures did not record it).
        no_backdrop = capture.settings.get("plain_backdrop") is False
        backdrops = None if no_backdrop else _plain_backdrop_maps(capture, config, posed, rgb)
        if backdrops is not None:
            # A plain backdrop has no features, so whatever plane the points hold is the object's own
            # base (the lego's plate), not a floor to leave out of the masks (plain_backdrop.py).
            plane = None
            if len(capture.points):
                is_object = np.linalg.norm(capture.points, axis=1) <= search
        elif capture.normalization is not None and len(capture.points):
            is_object = capture.normalization.object_point_mask(capture.points, radius)
            if is_floor(plane) and mask_config.ball_probable_fraction == 0:
                # The object was sized from points above a known floor: its ball is a good prior. Not
                # for a wall (the fox, a mounted head): the ball in front of a wall takes in picture
                # frames and the wall beside the object, and the points alone outline it better.
                mask_config = replace(mask_config, ball_probable_fraction=config.normalize.fill * radius / search)
        masks = automatic_masks(rgb, {f: capture.cameras[f] for f in posed}, capture.points, radius=search,
                                config=mask_config, progress=_stage(progress, "masks"), point_is_object=is_object,
                                support_plane=plane, observations=capture.observations or None, backdrops=backdrops)
        capture.log("backdrop", plain=backdrops is not None, plain_photos=len(backdrops or {}), photos=len(posed))
        source = "auto"
    else:
        folder = Path(mode)
        names = {f: capture.frames[f].record.original.name for f in posed}
        sizes = {f: (capture.cameras[f].width, capture.cameras[f].height) for f in posed}
        masks, reports = load_user_masks(folder, names, sizes=sizes)
        capture.reports.extend(reports)
        source = "user"
    for f in posed:
        if _cancelled(cancel):
            raise Cancelled("cancelled while writing masks")
        if f not in masks:
            capture.frames[f].mask_status = "no mask"
            continue
        problem = check_mask(masks[f])
        capture.write_mask(f, masks[f], source=source, status=problem or "ok")
        # Cut by the border: the view still holds valid rays (what is outside the frame is simply
        # not seen), but either the object was framed too tight or the mask took in background that
        # runs out of the picture; it is used, and named in the report.
        capture.frames[f].mask_warning = None if problem else cut_by_border(masks[f])
    _fit_world_to_masks(capture, config, {f: masks[f] for f in posed if f in masks}, trusted=source != "auto")
    capture.log("masks", source=source, ok=sum(capture.frames[f].mask_status == "ok" for f in posed))
    capture.save()


LEFT_OUT = "left out:"  # how a view's pose status begins when its pose disagrees with the others' outlines


def _outlines_without_poses(capture: Capture, config: CaptureConfig, backdrops) -> dict[str, np.ndarray] | None:
    """The object's outline in every photo, known without any pose (uint8, non-zero on the object, in
    the working images before undistortion): what is not a plain backdrop, or, for photos COLMAP
    posed that bring their own alpha, the alpha; None otherwise."""
    if backdrops is not None:
        return _backdrop_outlines(backdrops)
    if (capture.settings.get("pose_source") == "colmap"
            and _mask_mode(config, all(state.record.has_alpha for state in capture.frames.values())) == "alpha"):
        return {f: mask_from_alpha(capture.read_image(f, pinhole=False)) for f in capture.frames}
    return None


def _views_against_outlines(capture: Capture, config: CaptureConfig, source: dict, norm, outlines, sized: bool,
                            earlier: int) -> dict[str, float]:
    """The views structure from motion put on the wrong side of the object, shown by `outlines`
    (`_outlines_without_poses`; pose_silhouettes.py). `sized`: the world `norm` is already sized by
    them. `earlier`: views earlier rounds left out."""
    if capture.settings.get("pose_source") != "colmap" or outlines is None:
        return {}  # the user's own poses are taken as given
    posed = {f: o for f, o in outlines.items() if f in source}
    if not sized:
        # Sized by points or by the cameras alone, the object may reach out of the ball the hull is
        # carved in.
        norm = _size_by_outlines(norm, posed, source, config)
    return views_against_silhouettes(posed, {f: norm.apply_to_camera(source[f]) for f in posed},
                                     _mask_search_radius(config), config.pose_silhouettes, already_left_out=earlier)


def _posed_without(capture: Capture, left_out: dict[str, float], source: dict) -> dict:
    """The capture posed without the views `left_out` (frame -> share of its outline outside the
    others' hull): COLMAP maps its matches again without them (colmap_posing.map_again_without);
    should that lose more than a tenth of the other views, the first posing is kept and only the
    views and the points only they saw are dropped. Each view left out is unposed, with the reason.
    Returns the source cameras now posed."""
    kept = len(source) - len(set(left_out) & set(source))
    result = None
    if (capture.root / "colmap").is_dir():
        try:
            result = map_again_without(capture.root / "colmap", sorted(left_out), capture.records)
        except LirmUserError as e:
            log.warning("could not map the photos again without the views left out: %s", e)
    mapped_again = result is not None and len(result.cameras) >= 0.9 * kept
    if mapped_again:
        _apply_posing(capture, result)
        source = dict(capture.cameras)
    else:
        source = {f: c for f, c in source.items() if f not in left_out}
        for f in left_out:
            capture.settings["source_cameras"].pop(f, None)
            capture.observations.pop(f, None)
        _keep_points_seen_by_posed_views(capture)
    for f, share in left_out.items():
        capture.frames[f].pose_status = (
            f"{LEFT_OUT} its pose disagreed with the other photos' outlines ({100 * share:.0f}% of the object's "
            "outline fell where they see none): structure from motion likely put it on the wrong side of an object "
            "that looks alike from two sides")
    capture.log("poses against outlines", left_out={f: round(v, 3) for f, v in left_out.items()},
                mapped_again=mapped_again)
    return source


def _keep_points_seen_by_posed_views(capture: Capture) -> None:
    """Drop the sparse points that only views now unposed observed (they were triangulated from
    the wrong poses), renumbering the observations."""
    if not capture.observations or not len(capture.points):
        return
    seen = np.zeros(len(capture.points), bool)
    for indices in capture.observations.values():
        seen[np.asarray(indices, dtype=np.int64)] = True
    renumber = np.cumsum(seen) - 1
    capture.points = capture.points[seen]
    capture.observations = {f: renumber[np.asarray(v, dtype=np.int64)] for f, v in capture.observations.items()}


def _size_by_outlines(norm, outlines: dict[str, np.ndarray], source: dict, config: CaptureConfig):
    """`norm` moved so that the hull of `outlines` (uint8, the photos' sizes, non-zero on the object;
    in the source cameras' images) fills the ball (fit_to_silhouettes.py). Every outline carves (a
    backdrop's or an alpha's is the object's own, a little fat if anything): with the automatic
    masks' tolerance of a few disagreeing views, the lego's 30 views on white left a hull reaching
    0.7 from the origin where the object ended at 0.1, and the world was sized to that."""
    fit = size_world_from_silhouettes(outlines, {f: norm.apply_to_camera(source[f]) for f in outlines},
                                      config.normalize.target_radius, config.normalize.fill, _mask_search_radius(config),
                                      trusted_masks=True)
    if fit is None or not fit.moved:
        return norm
    return moved_normalization(norm, fit.scale, fit.shift)


def _backdrop_outlines(backdrops: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """What is not backdrop, per photo: the object's outline before any mask (plain_backdrop.py)."""
    return {f: np.where(m == BACKDROP, 0, 255).astype(np.uint8) for f, m in backdrops.items()}


def _plain_backdrop_maps(capture: Capture, config: CaptureConfig, frames,
                         images: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray] | None:
    """The backdrop maps of `frames`' photos (the working images, or `images`) when the capture was
    shot on a plain backdrop (plain_backdrop.py), else None; only for automatic masks (alpha and the
    user's masks need no backdrop)."""
    if _mask_mode(config, all(capture.frames[f].record.has_alpha for f in frames)) != "automatic":
        return None
    if images is None:
        images = {f: capture.read_image(f, pinhole=False)[:, :, :3] for f in frames}
    return plain_backdrop_capture(images, config.backdrop)


def _mask_mode(config: CaptureConfig, all_have_alpha: bool) -> str:
    """What the masks stage will do: "alpha", "automatic" or a folder (`--masks auto` takes the alpha
    when every photo has one)."""
    if config.masks == "auto":
        return "alpha" if all_have_alpha else "automatic"
    return config.masks


def _mask_search_radius(config: CaptureConfig) -> float:
    """The ball the automatic masks look for the object in. Normalisation maps the object's
    estimated radius to fill * R, leaving 1 / fill of room; the estimate comes from sparse points,
    which miss dark and smooth parts (the WaterBottle's cap), so the masks get the same room again.
    Searched within R itself, the cap sat on the ball's outline and one level of rounding in the
    photos flipped it in or out of 12 of 16 masks (IoU 0.95 / 0.86); within R / fill: 0.96 / 0.97,
    and 0.99 for the floor-lit shoot (0.82 before). README, "Captures"."""
    return config.normalize.target_radius / config.normalize.fill


def _fit_world_to_masks(capture: Capture, config: CaptureConfig, masks: dict[str, np.ndarray], trusted: bool) -> None:
    """When the masks' hull rises out of the ball, move the world so the object fits it; when the world
    was sized from the cameras alone (no sparse points: imported poses), size it from the hull
    (engine/capture/fit_to_silhouettes.py). The masks, being pixels, stay as they are."""
    if capture.normalization is None:
        return
    if capture.normalization.used_points == 0:
        fit = size_world_from_silhouettes(masks, capture.cameras, config.normalize.target_radius, config.normalize.fill,
                                          _mask_search_radius(config), trusted_masks=trusted)
    else:
        fit = fit_world_to_silhouettes(masks, capture.cameras, capture.normalization, config.normalize.target_radius,
                                       config.normalize.fill, _mask_search_radius(config))
    if fit is None or not fit.moved:
        return
    capture.cameras = {f: moved_camera(c, fit.scale, fit.shift) for f, c in capture.cameras.items()}
    if len(capture.points):
        capture.points = fit.scale * (capture.points - fit.shift)
    capture.normalization = moved_normalization(capture.normalization, fit.scale, fit.shift)
    capture.log("fit to masks", top=round(fit.top, 4), scale=round(fit.scale, 4),
                shift=[round(float(v), 4) for v in fit.shift])


def _crops(capture: Capture, config: CaptureConfig, progress, cancel) -> None:
    posed = sorted(capture.cameras)
    done = 0
    gains, response = capture_exposure_gains(capture), capture_response(capture)  # one exposure (exposure_match.py)
    for f in posed:
        if _cancelled(cancel):
            raise Cancelled("cancelled while cropping")
        mask = capture.read_mask(f)
        state = capture.frames[f]
        if mask is None or state.mask_status != "ok":
            continue
        try:
            view = prepare_view(f, exposure_matched_image(capture, f, gains, response)[:, :, :3], mask, capture.cameras[f],
                                config.crop)
        except EmptyMaskError:
            state.mask_status = "empty"
            continue
        capture.write_prepared(view)
        done += 1
        if progress:
            progress("crops", done, len(posed))
    # ("exposure_matched": the working copies were matched, in exposure or white balance or both)
    matched = {"exposure_matched": True,
               "brightened_up_to_stops": round(float(np.log2(max(float(np.max(g)) for g in gains.values()))), 2)} if gains else {}
    capture.log("crops", prepared=done, size=config.crop.size, **matched)
    capture.save()


def _lighting(capture: Capture, config: CaptureConfig, cancel) -> None:
    """The environment the photos were taken in, from their backgrounds (engine/lighting/). A capture
    whose photos show no background (cut-outs) simply has none: that is said, not an error."""
    frames = [f for f in sorted(capture.cameras) if capture.frames[f].mask_status == "ok"]
    images, masks = {}, {}
    for f in frames:
        mask = capture.read_mask(f)
        if mask is not None:
            images[f], masks[f] = capture.read_image(f), mask
    plane = capture.normalization.plane if capture.normalization is not None else None
    # The photos at one exposure and white balance (exposure_match.py), through the curve tried: the
    # exposure by their EXIF when every photo has it, else by what their shared backgrounds say; the
    # balance by the backgrounds (exposure_estimate.py); estimated again here from this run's photos.
    capture.settings.pop(ESTIMATED_EXPOSURE_KEY, None)
    exif = {frame_id: state.record.exposure_stops for frame_id, state in capture.frames.items()}

    def estimate(response: str):
        curve = replace(config.lighting, response=response)
        try:
            found = estimate_exposure_stops(images, masks, capture.cameras, curve, plane, cancel)
            used = matching_gains(exif, estimate_record(found) if found is not None else None)
            matched = {f: match_exposure(image, used[f], response) if f in used else image
                       for f, image in images.items()} if used else images
            return estimate_capture_lighting(matched, masks, capture.cameras, curve, cancel=cancel, support_plane=plane), found
        except InterruptedError as error:
            raise Cancelled(str(error)) from error
        except ValueError as error:
            capture.log("lighting", estimated=False, reason=str(error))
            capture.save()
            return None, None

    # Clipping is judged on the display values, whatever the curve: estimate once, then again through
    # the curve the clipped share chooses (about 2 s).
    lighting, found = estimate(config.camera_response if config.camera_response in RESPONSES else "aces")
    if lighting is None:
        return
    response, why = response_for_capture(config.camera_response, bool(capture.settings.get("plain_backdrop")),
                                         lighting.clipped_fraction)
    if response != lighting.config.response:
        lighting, found = estimate(response)
        if lighting is None:
            return
    exposures = {}
    if found is not None:
        capture.settings[ESTIMATED_EXPOSURE_KEY] = estimate_record(found)
        exposures = {"exposure_estimated_spread": round(found.spread, 2), "exposure_matched": found.worth_matching,
                     "white_balance_spread": round(found.colour_spread, 3), "white_balance_matched": found.colour_worth_matching}
    path = lighting.save(capture.root)
    capture.log("lighting", estimated=True, file=str(path.relative_to(capture.root)), photos=lighting.photos_used,
                seen=round(lighting.seen_fraction, 3), clipped=round(lighting.clipped_fraction, 3),
                camera_response=response, camera_response_why=why, **exposures)
    capture.save()


# ---- helpers --------------------------------------------------------------------------------------
def _mark(capture: Capture, stage: str) -> None:
    completed = capture.settings.setdefault("completed", [])
    if stage not in completed:
        completed.append(stage)
    capture.save()


def _summary(capture: Capture) -> CaptureSummary:
    frames = capture.frames.values()
    return CaptureSummary(
        capture=capture,
        accepted=len(capture.frames),
        skipped=sum(not r.accepted for r in capture.reports),
        registered=len(capture.cameras),
        masked=sum(s.mask_status == "ok" for s in frames),
        prepared=sum(capture.prepared_path(f).exists() for f in capture.cameras),
    )


def _stage(progress: Progress | None, name: str):
    return (lambda done, total: progress(name, done, total)) if progress else None


def _substages(progress: Progress | None, name: str):
    """For a stage that reports its own parts (COLMAP: extract, match, map) as "name: part"."""
    return (lambda part, done, total: progress(f"{name}: {part}", done, total)) if progress else None


def _cancelled(cancel) -> bool:
    return bool(cancel and cancel())


def _settings(config: CaptureConfig) -> dict:
    return {"config": _jsonable(asdict(config))}


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value
