"""Ground-truth views of one object for the network: what the capture pipeline would hand it (masked
image on white, the unmasked image with the environment behind, Plücker rays) plus the true mask,
albedo, roughness, metallic and normal maps to supervise it.

The object is scaled into a sphere of `object_radius` inside the field's R = 1 (the paper's objects
sit inside the bounding sphere with some room). Cameras follow the supplementary's test protocol:
FoV 50 degrees, at the distance where the bounding sphere just fits.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.cameras import Camera, distance_to_cover_sphere, orbit_camera
from lirm.engine.model.lirm import ViewBatch
from lirm.engine.orbit_render import normalizing_transform
from lirm.renderer.environment import Environment
from lirm.renderer.mesh import MeshData
from lirm.renderer.pbr_renderer import Lighting, PBRRenderer, RenderSettings


@dataclass(frozen=True)
class ObjectViewsConfig:
    object_name: str = "vase"
    seed: int = 0
    size: int = 64
    supersample: int = 2
    fov_deg: float = 50.0
    object_radius: float = 0.8


@dataclass
class ObjectViews:
    cameras: list[Camera]
    image: np.ndarray  # (V, S, S, 3) display sRGB object on white
    image_bg: np.ndarray  # (V, S, S, 3) display sRGB with the environment behind
    mask: np.ndarray  # (V, S, S) coverage in [0, 1]
    albedo: np.ndarray  # (V, S, S, 3) linear base colour, 0 off the object
    roughness: np.ndarray  # (V, S, S)
    metallic: np.ndarray  # (V, S, S)
    normal: np.ndarray  # (V, S, S, 3) world normals, 0 off the object
    depth: np.ndarray | None = None  # (V, S, S) camera-space z, 0 off the object

    def select(self, indices) -> "ObjectViews":
        """The views at `indices`, in that order."""
        idx = list(indices)
        pick = lambda a: None if a is None else a[idx]  # noqa: E731
        return ObjectViews([self.cameras[i] for i in idx], pick(self.image), pick(self.image_bg), pick(self.mask),
                           pick(self.albedo), pick(self.roughness), pick(self.metallic), pick(self.normal), pick(self.depth))

    def view_batch(self, indices: list[int] | None = None, device: str | torch.device = "cpu") -> ViewBatch:
        idx = list(range(len(self.cameras))) if indices is None else list(indices)
        plucker = np.stack([self.cameras[i].plucker() for i in idx])
        return ViewBatch.from_arrays(self.image[idx], self.image_bg[idx], plucker, device)


def protocol_cameras(azimuths_deg: list[float], elevations_deg: list[float], size: int, fov_deg: float = 50.0,
                     radius: float = 1.0) -> list[Camera]:
    """Cameras looking at the origin from where the sphere of `radius` just fills the field of view."""
    distance = distance_to_cover_sphere(radius, fov_deg)
    return [orbit_camera(a, e, distance, size, size, fov_deg, axis="min") for a, e in zip(azimuths_deg, elevations_deg)]


def render_object_views(renderer: PBRRenderer, environment: Environment, cameras: list[Camera],
                        config: ObjectViewsConfig = ObjectViewsConfig()) -> ObjectViews:
    model = resolve_asset(config.object_name, seed=config.seed)
    transform = normalizing_transform(model.bounds)
    transform[:3] *= config.object_radius
    lighting = renderer.prepare_lighting(environment)
    try:
        return render_meshes(renderer, lighting, model.meshes, transform, cameras, config.supersample)
    finally:
        lighting.maps.release()


def render_meshes(renderer: PBRRenderer, lighting: Lighting, meshes: list[MeshData], transform: np.ndarray,
                  cameras: list[Camera], supersample: int = 2, exposure_ev: float = 0.0) -> ObjectViews:
    """Every camera (all of one size) of the meshes under prepared lighting, with the G-buffer."""
    sizes = {(c.width, c.height) for c in cameras}
    if len(sizes) != 1:
        raise ValueError(f"the cameras must share one image size, got {sorted(sizes)}")
    scene = renderer.upload(meshes, transform)
    settings = RenderSettings(supersample=supersample, exposure_ev=exposure_ev)
    # On black, the supersampled beauty is the object premultiplied by its coverage.
    on_black = replace(settings, show_environment=False, clear_color=(0.0, 0.0, 0.0))
    outs, premultiplied = [], []
    try:
        for camera in cameras:
            outs.append(renderer.render_view(scene, camera, lighting, settings))
            premultiplied.append(renderer.render_view(scene, camera, lighting, on_black).beauty)
    finally:
        scene.release()
    mask = np.stack([o.mask for o in outs]).astype(np.float32)
    image_bg = np.stack([o.beauty for o in outs]).astype(np.float32)
    # With the environment on it is the photo; over white is what the capture's crop gives.
    image = np.stack(premultiplied) + (1.0 - mask[..., None])
    return ObjectViews(cameras, np.clip(image, 0, 1).astype(np.float32), np.clip(image_bg, 0, 1), mask,
                       np.stack([o.albedo for o in outs]).astype(np.float32), np.stack([o.roughness for o in outs]).astype(np.float32),
                       np.stack([o.metallic for o in outs]).astype(np.float32), np.stack([o.normal for o in outs]).astype(np.float32),
                       np.stack([o.depth for o in outs]).astype(np.float32))
