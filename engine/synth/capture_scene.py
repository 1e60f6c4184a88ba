"""A synthetic photo shoot: a built-in object on a textured ground plane under an HDR environment,
photographed from orbit views, with the true cameras and object masks kept as ground truth.

Used by `lirm demo` and the capture tests to run the capture pipeline on images whose answer is known.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.cameras import Camera, distance_to_cover_sphere, orbit_camera
from lirm.engine.orbit_render import normalizing_transform
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.mesh import MeshData
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.primitives import quad

from .texture_patterns import value_noise


@dataclass(frozen=True)
class SyntheticCaptureConfig:
    object_name: str = "mug"
    seed: int = 0
    views: int = 16
    width: int = 640
    height: int = 480
    fov_deg: float = 50.0
    # One ring: neighbours 22.5 degrees apart. Alternating 20/40 degree rings registered only 2 of 16
    # views (too much viewpoint change between neighbours on the textured floor), one ring 16 of 16.
    elevations_deg: tuple[float, ...] = (30.0,)
    distance_scale: float = 1.35  # times the distance at which the unit sphere fills the view
    ground_size: float = 12.0
    supersample: int = 2


@dataclass
class SyntheticCapture:
    images: dict[str, np.ndarray]  # frame id -> (H, W, 3) uint8 sRGB photo
    cameras: dict[str, Camera]  # true cameras; the object is normalised into the unit sphere at the origin
    masks: dict[str, np.ndarray]  # true object masks, uint8 255 = object
    object_name: str


def ground_plane(size: float, z: float, seed: int, texture_size: int = 2048) -> MeshData:
    """A matte gravel-like floor: dense, non-repeating detail for structure-from-motion to match
    (a tiled or periodic floor would give it false matches), unlike the object it surrounds."""
    rng = np.random.default_rng(seed)
    n = texture_size
    noise = value_noise(rng, n, n, cells=(16, 16), octaves=4)
    base = np.stack([0.50 + 0.30 * noise, 0.46 + 0.24 * noise, 0.40 + 0.18 * noise], -1)
    texture = np.clip(base * 255, 0, 255).astype(np.uint8)
    for _ in range(6000):  # pebbles of random size and tone
        centre = tuple(int(c) for c in rng.integers(0, n, 2))
        tone = rng.uniform(0.25, 1.0)
        colour = tuple(int(c) for c in np.clip(np.array([170, 150, 120]) * tone + rng.normal(0, 20, 3), 0, 255))
        cv2.circle(texture, centre, int(rng.integers(2, 9)), colour, -1, lineType=cv2.LINE_AA)
    mesh = quad(size=size, material=PBRMaterial(name="ground", base_color_texture=texture, metallic_factor=0.0, roughness_factor=0.85))
    mesh.positions[:, 2] = z
    return mesh


def synthetic_cameras(config: SyntheticCaptureConfig) -> dict[str, Camera]:
    distance = distance_to_cover_sphere(1.0, config.fov_deg) * config.distance_scale
    cams = {}
    for i in range(config.views):
        elevation = config.elevations_deg[i % len(config.elevations_deg)]
        azimuth = 360.0 * i / config.views
        cams[f"{i + 1:04d}"] = orbit_camera(azimuth, elevation, distance, config.width, config.height, config.fov_deg, axis="min")
    return cams


def render_synthetic_capture(renderer: PBRRenderer, environment: Environment, config: SyntheticCaptureConfig = SyntheticCaptureConfig()) -> SyntheticCapture:
    model = resolve_asset(config.object_name, seed=config.seed)
    transform = normalizing_transform(model.bounds)
    lowest = float(((np.concatenate([m.positions for m in model.meshes]) @ transform[:3, :3].T) + transform[:3, 3])[:, 2].min())
    ground = ground_plane(config.ground_size, lowest, config.seed)
    # The ground is already in the normalised world; undo the scene transform for it.
    ground.positions = (ground.positions - transform[:3, 3]) @ np.linalg.inv(transform[:3, :3]).T
    ground.normals = ground.normals @ transform[:3, :3]
    ground.normals /= np.linalg.norm(ground.normals, axis=1, keepdims=True)
    cameras = synthetic_cameras(config)
    lighting = renderer.prepare_lighting(environment)
    with_ground = renderer.upload(model.meshes + [ground], transform)
    object_only = renderer.upload(model.meshes, transform)
    settings = RenderSettings(supersample=config.supersample)
    images, masks = {}, {}
    try:
        for fid, cam in cameras.items():
            images[fid] = np.clip(np.round(renderer.render_view(with_ground, cam, lighting, settings).beauty * 255), 0, 255).astype(np.uint8)
            masks[fid] = np.where(renderer.render_view(object_only, cam, lighting, settings).mask > 0.5, 255, 0).astype(np.uint8)
    finally:
        with_ground.release()
        object_only.release()
        lighting.maps.release()
    return SyntheticCapture(images, cameras, masks, config.object_name)
