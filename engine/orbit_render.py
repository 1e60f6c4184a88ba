"""Render an asset from an orbit of cameras and write the beauty, the linear HDR radiance and every
G-buffer channel as image files, with a nerfstudio-style transforms.json describing the cameras.

Layout of the output folder (frame i = 000, 001, ...):
  beauty/i.png      tone-mapped sRGB (RGBA with coverage as alpha when the background is off)
  radiance/i.exr    linear HDR radiance before exposure and tone mapping
  albedo/i.png      base colour, sRGB-encoded for viewing (the G-buffer itself is linear)
  roughness/i.png   metallic/i.png   linear, 8-bit grey
  normal/i.png      world normal as (n + 1) / 2
  depth/i.png       16-bit, camera z in units of `depth_unit_scale_factor` (0 = empty)
  mask/i.png        coverage
  transforms.json   OpenCV intrinsics, OpenGL camera-to-world per frame (nerfstudio convention)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import PBRRenderer, RenderOutput, RenderSettings
from lirm.renderer.tonemap import linear_to_srgb

from .assets.model_loader import LoadedModel
from .cameras import Camera, distance_to_cover_sphere, orbit_cameras
from .io.atomic_files import atomic_write_json
from .io.images import to_uint8, write_exr, write_png

CHANNELS = ("beauty", "radiance", "albedo", "roughness", "metallic", "normal", "depth", "mask")
# The G-buffer takes 88 bytes a pixel (five RGBA float targets, depth, display): 8192² is ~6 GB.
MAX_RENDER_SIDE = 8192
DEPTH_UNIT = 1e-4  # 16-bit depth in 0.1 mm of scene units: 6.5 units of range, ample for a unit sphere


@dataclass
class OrbitRenderConfig:
    views: int = 8
    width: int = 512
    height: int = 512
    elevation_deg: float = 20.0
    fov_deg: float = 40.0
    start_azimuth_deg: float = 0.0  # 0 = in front of the object (looking along +Y)
    supersample: int = 2
    background: bool = True
    exposure_ev: float = 0.0
    environment_rotation_deg: float = 0.0
    normalize: bool = True  # scale and centre the asset into the unit sphere at the origin
    margin: float = 1.05  # camera distance covers the bounding sphere times this
    tonemapper: str = "aces"  # RenderSettings.tonemapper ("linear": a capture's lighting read through plain sRGB)

    def __post_init__(self) -> None:
        if self.views < 1:
            raise ValueError("views must be at least 1")
        if not (16 <= self.width <= 8192 and 16 <= self.height <= 8192):
            raise ValueError(f"image size {self.width}x{self.height} must be between 16 and 8192 pixels a side")
        longest = max(self.width, self.height) * self.supersample
        if longest > MAX_RENDER_SIDE:
            raise ValueError(
                f"{self.width}x{self.height} with supersample {self.supersample} renders {longest} pixels a side, "
                f"more than {MAX_RENDER_SIDE}: lower --size or --supersample"
            )
        if not 1.0 < self.fov_deg < 170.0:
            raise ValueError("fov_deg must be between 1 and 170 degrees")


@dataclass
class OrbitRenderResult:
    out_dir: Path
    cameras: list[Camera]
    files: dict[str, list[Path]] = field(default_factory=dict)


def normalizing_transform(bounds: np.ndarray) -> np.ndarray:
    """Uniform scale and translation taking the box's bounding sphere to the unit sphere."""
    center = bounds.mean(axis=0)
    radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2.0, 1e-9)
    t = np.eye(4)
    t[:3, :3] /= radius
    t[:3, 3] = -center / radius
    return t


def orbit_for(config: OrbitRenderConfig, radius: float = 1.0) -> list[Camera]:
    distance = distance_to_cover_sphere(radius * config.margin, config.fov_deg)
    return orbit_cameras(
        config.views, config.elevation_deg, distance, config.width, config.height, config.fov_deg,
        start_azimuth_deg=config.start_azimuth_deg, axis="min",
    )


def render_orbit(
    renderer: PBRRenderer,
    model: LoadedModel,
    environment: Environment,
    config: OrbitRenderConfig,
    out_dir: str | Path,
    progress: Callable[[int, int], None] | None = None,
    cameras: list[Camera] | None = None,
) -> OrbitRenderResult:
    """Render from an orbit of `config.views` cameras around the (normalised) asset, or, when
    `cameras` are given (`lirm render --cameras`), from exactly those cameras with the asset kept in
    its own frame: an original and its reconstruction then render from the same cameras."""
    out_dir = Path(out_dir)
    transform = normalizing_transform(model.bounds) if config.normalize and cameras is None else np.eye(4)
    scene = renderer.upload(model.meshes, transform)
    lighting = renderer.prepare_lighting(environment, rotation_deg=config.environment_rotation_deg)
    settings = RenderSettings(exposure_ev=config.exposure_ev, show_environment=config.background, supersample=config.supersample,
                              tonemapper=config.tonemapper)
    if cameras is None:
        radius = 1.0 if config.normalize else float(np.linalg.norm(scene.bounds[1] - scene.bounds[0])) / 2.0
        cameras = orbit_for(config, radius)
        if not config.normalize:  # orbit around the asset's own centre
            center = scene.bounds.mean(axis=0)
            cameras = [c.with_pose(_translated(c.c2w, center)) for c in cameras]
    result = OrbitRenderResult(out_dir, cameras, {name: [] for name in CHANNELS})
    frames = []
    try:
        for i, camera in enumerate(cameras):
            out = renderer.render_view(scene, camera, lighting, settings)
            paths = write_render_output(out, out_dir, f"{i:03d}", with_alpha=not config.background)
            for name, p in paths.items():
                result.files[name].append(p)
            frame = {"file_path": _rel(paths["beauty"], out_dir), **camera.to_dict()}
            frame.update({f"{name}_file_path": _rel(p, out_dir) for name, p in paths.items() if name != "beauty"})
            frame["mask_path"] = frame["mask_file_path"]  # the key nerfstudio reads
            frames.append(frame)
            if progress is not None:
                progress(i + 1, len(cameras))
    finally:
        scene.release()
        lighting.maps.release()
    atomic_write_json(out_dir / "transforms.json", {
        "camera_model": "OPENCV",
        "depth_unit_scale_factor": DEPTH_UNIT,
        "frames": frames,
        "lirm": {
            "asset": str(model.source),
            "environment": environment.name,
            "asset_to_world": transform.tolist(),
            "render": asdict(config),
            "conventions": "transform_matrix: OpenGL camera-to-world (nerfstudio); world +Z up; "
                           "albedo PNG sRGB-encoded, roughness/metallic linear, normal = (n + 1) / 2",
        },
    })
    return result


def cameras_of_capture(capture_dir: str | Path, asset: str | Path) -> list[Camera]:
    """The posed cameras of a capture folder (frame order), in the frame of `asset`, an export of it:
    the export stands the asset on the ground and records where (glb_placement), and the cameras
    are moved the same way, so that each render lines up with its photo."""
    from .capture.capture_folder import Capture
    from .errors import LirmUserError
    from .export.glb_placement import read_placement

    capture_dir = Path(capture_dir)
    if not (capture_dir / "capture.json").is_file():
        raise LirmUserError(f"{capture_dir}: a folder, but not a capture (no capture.json); pass a capture folder "
                            f"or a transforms.json")
    capture = Capture.open(capture_dir)
    if not capture.cameras:
        raise LirmUserError(f"{capture_dir}: no posed photo to render from")
    placement = read_placement(asset)
    if placement is None:
        raise LirmUserError(f"{asset}: it does not say where it was placed (not a `lirm export` .glb), so the capture's "
                            f"cameras cannot be put where it is; pass a transforms.json in the asset's own frame instead")
    return [capture.cameras[f].moved_by(placement) for f in sorted(capture.cameras)]


def cameras_from_transforms(path: str | Path) -> list[Camera]:
    """Every frame's camera of a nerfstudio / NeRF transforms.json, in file order (intrinsics from
    the frame or the top level; w and h are needed: the image size to render)."""
    import json

    from .errors import LirmUserError

    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise LirmUserError(f"{path}: file not found (expected a transforms.json with cameras)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise LirmUserError(f"{path}: cannot read it as JSON ({e})") from None
    if not isinstance(data, dict) or not isinstance(data.get("frames"), list) or not data["frames"]:
        raise LirmUserError(f"{path}: no 'frames' list; pass a transforms.json (e.g. one `lirm render` wrote)")
    top = {k: v for k, v in data.items() if k != "frames"}
    cameras = []
    for k, frame in enumerate(data["frames"]):
        try:
            cameras.append(Camera.from_dict({**top, **frame}))
        except (ValueError, TypeError, KeyError) as e:
            raise LirmUserError(f"{path}: frame {k}: {e}") from None
    return cameras


def write_render_output(out: RenderOutput, out_dir: Path, stem: str, with_alpha: bool) -> dict[str, Path]:
    mask8 = to_uint8(out.mask)
    beauty = to_uint8(out.beauty)
    if with_alpha:
        beauty = np.dstack([beauty, mask8])
    depth = np.where(out.mask > 0, np.round(out.depth / DEPTH_UNIT), 0)
    return {
        "beauty": write_png(out_dir / "beauty" / f"{stem}.png", beauty),
        "radiance": write_exr(out_dir / "radiance" / f"{stem}.exr", out.radiance),
        "albedo": write_png(out_dir / "albedo" / f"{stem}.png", to_uint8(linear_to_srgb(out.albedo))),
        "roughness": write_png(out_dir / "roughness" / f"{stem}.png", to_uint8(out.roughness)),
        "metallic": write_png(out_dir / "metallic" / f"{stem}.png", to_uint8(out.metallic)),
        "normal": write_png(out_dir / "normal" / f"{stem}.png", to_uint8(np.where(out.mask[..., None] > 0, (out.normal + 1) / 2, 0))),
        "depth": write_png(out_dir / "depth" / f"{stem}.png", np.clip(depth, 0, 65535).astype(np.uint16)),
        "mask": write_png(out_dir / "mask" / f"{stem}.png", mask8),
    }


def _translated(c2w: np.ndarray, offset: np.ndarray) -> np.ndarray:
    moved = np.array(c2w, dtype=np.float64)
    moved[:3, 3] += offset
    return moved


def _rel(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()
