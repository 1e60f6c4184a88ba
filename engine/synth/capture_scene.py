"""A synthetic photo shoot: a built-in object on a textured ground plane under an HDR environment,
photographed from orbit views, with the true cameras and object masks kept as ground truth.

The object is lit by what surrounds it on the set: the environment above, the lit ground below
(`environment_around_object`). A real object on a table gets the table's light too, and the photos'
backgrounds show that table; lighting the object by the bare environment instead (its own, darker
ground) would make a shoot whose backgrounds contradict its lighting, and the capture's lighting
estimate, which reads them, could never agree with the truth.

Used by `lirm demo` and the capture tests to run the capture pipeline on images whose answer is known.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.cameras import Camera, distance_to_cover_sphere, look_at, orbit_camera
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
    # The object lit by the floor too (environment_around_object), as a real object on a table is;
    # False: by the bare environment, as every shoot was until the capture lighting needed the truth.
    floor_lights_object: bool = True


@dataclass
class SyntheticCapture:
    images: dict[str, np.ndarray]  # frame id -> (H, W, 3) uint8 sRGB photo
    cameras: dict[str, Camera]  # true cameras; the object is normalised into the unit sphere at the origin
    masks: dict[str, np.ndarray]  # true object masks, uint8 255 = object
    object_name: str
    lit_by: Environment  # what lit the object: the environment with the lit ground below (environment_around_object)


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
    ground_world = ground_plane(config.ground_size, lowest, config.seed)
    # The ground is built in the normalised world; the scene is uploaded with the model's transform, so undo it for the ground.
    normals = ground_world.normals @ transform[:3, :3]
    ground = replace(ground_world, positions=(ground_world.positions - transform[:3, 3]) @ np.linalg.inv(transform[:3, :3]).T,
                     normals=normals / np.linalg.norm(normals, axis=1, keepdims=True))
    cameras = synthetic_cameras(config)
    lit_by = environment_around_object(renderer, environment, ground_world) if config.floor_lights_object else environment
    # One lighting for the whole set: the ground faces up, so its light (the upper hemisphere) is the
    # environment's own; the backdrop beyond the ground's edge shows the ground's far band, as the object sees it.
    lighting = renderer.prepare_lighting(lit_by)
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
    return SyntheticCapture(images, cameras, masks, config.object_name, lit_by)


# The five cube faces that can see a floor below the origin: down and the four horizontal sides.
_FLOOR_FACES = ((0.0, 0.0, -1.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0))


def environment_around_object(renderer: PBRRenderer, environment: Environment, ground: MeshData,
                              face_size: int = 512) -> Environment:
    """The environment as an object at the origin sees it on the set: where the `ground` (in the
    world frame, facing up) lies between it and the environment, the ground's own radiance toward
    the origin (rendered under `environment` from the origin, one 90-degree cube face at a time);
    elsewhere the environment. Same size and frame as `environment`.

    The renderer has no global illumination, so the light the ground sends the object is baked into
    the environment that lights it; what the ground shows the cameras is the same surface lit the same way.
    """
    directions, _ = environment.texel_directions()
    flat = directions.reshape(-1, 3)
    radiance = environment.radiance.reshape(-1, 3).astype(np.float64).copy()
    below = np.nonzero(flat[:, 2] < 0.0)[0]
    faces = np.array(_FLOOR_FACES)
    face_of = np.argmax(flat[below] @ faces.T, axis=1)
    scene = renderer.upload([ground], np.eye(4))
    lighting = renderer.prepare_lighting(environment)
    half = face_size / 2.0
    settings = RenderSettings(show_environment=False, supersample=1)
    try:
        for index, axis in enumerate(faces):
            chosen = below[face_of == index]
            if not len(chosen):
                continue
            up = (0.0, 1.0, 0.0) if axis[2] else (0.0, 0.0, 1.0)
            camera = Camera(face_size, face_size, half, half, half, half, look_at((0.0, 0.0, 0.0), axis, up))
            view = renderer.render_view(scene, camera, lighting, settings)
            local = flat[chosen] @ camera.c2w[:3, :3]  # world -> camera (OpenCV: x right, y down, z forward)
            x = half * local[:, 0] / local[:, 2] + half - 0.5  # pixel coordinates, 0 at the first pixel's centre
            y = half * local[:, 1] / local[:, 2] + half - 0.5
            coverage = _bilinear(view.mask[..., None], x, y)
            radiance[chosen] = coverage * _bilinear(view.radiance, x, y) + (1.0 - coverage) * radiance[chosen]
    finally:
        scene.release()
        lighting.maps.release()
    return Environment(radiance.reshape(environment.radiance.shape).astype(np.float32),
                       name=f"{environment.name} over the ground")


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(H, W, C) image at pixel coordinates x, y (0 at the first pixel's centre), edges clamped -> (N, C)."""
    h, w = image.shape[:2]
    x, y = np.clip(x, 0.0, w - 1.0), np.clip(y, 0.0, h - 1.0)
    x0, y0 = np.minimum(x.astype(np.int64), w - 2), np.minimum(y.astype(np.int64), h - 2)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = image[y0, x0] * (1.0 - fx) + image[y0, x0 + 1] * fx
    bottom = image[y0 + 1, x0] * (1.0 - fx) + image[y0 + 1, x0 + 1] * fx
    return top * (1.0 - fy) + bottom * fy
