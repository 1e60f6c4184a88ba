"""Random training scenes as the supplementary describes them (section "Training datasets creation").

One scene, fully determined by its seed: a built-in object (its variant picked by the seed) turned
about +Z and scaled into the bounding sphere, under a randomly rotated environment, photographed by
32 cameras with FoV U(15, 85) degrees, elevation U(-5, 70), azimuth U(0, 360), each at the distance
where the bounding sphere just fits its field of view. Augmentations:
- auto-exposure: the exposure meters the environment so that its average radiance maps to the
  same brightness (real cameras do this; without it bright and dark HDRs would span 10 stops);
- white balance: a small random tint of the lighting, as a camera's white balance would leave;
- the "specular copy": with probability `specular_copy_probability` every roughness is scaled by
  U(0.3, 0.6), the supplementary's second dataset that makes reflections visible.
The pixel-scale perturbation U(0.75, 1.25) is applied on the fly by training, not here.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.assets.environment_files import resolve_environment
from lirm.engine.cameras import Camera, distance_to_cover_sphere, orbit_camera
from lirm.engine.orbit_render import normalizing_transform
from lirm.renderer.environment import Environment
from lirm.renderer.mesh import MeshData
from lirm.renderer.pbr_renderer import PBRRenderer
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS, PROCEDURAL_ENVIRONMENTS

from .object_views import ObjectViews, render_meshes
from .procedural_objects import BUILTIN_OBJECTS

GENERATOR_VERSION = 1  # bump when a change would alter the scenes a seed produces


@dataclass(frozen=True)
class TrainingSceneConfig:
    views: int = 32
    size: int = 256
    supersample: int = 2
    fov_deg: tuple[float, float] = (15.0, 85.0)
    elevation_deg: tuple[float, float] = (-5.0, 70.0)
    object_radius: tuple[float, float] = (0.7, 0.9)  # the object's bounding radius inside R = 1
    objects: tuple[str, ...] = BUILTIN_OBJECTS
    environments: tuple[str, ...] = tuple(PROCEDURAL_ENVIRONMENTS)
    environment_width: int = 512
    white_balance: float = 0.1  # per-channel lighting gain U(1 - wb, 1 + wb), then renormalised
    specular_copy_probability: float = 0.5
    specular_roughness_scale: tuple[float, float] = (0.3, 0.6)


@dataclass
class SceneDescription:
    """Everything the seed decided, for logs and contact sheets."""

    seed: int
    object_name: str
    object_variant: int
    object_turn_deg: float
    object_radius: float
    environment: str
    environment_rotation_deg: float
    exposure_ev: float
    tint: tuple[float, float, float]
    roughness_scale: float
    cameras: list[dict] = field(default_factory=list)  # azimuth, elevation, fov per view


@dataclass
class TrainingScene:
    description: SceneDescription
    views: ObjectViews


def sample_cameras(rng: np.random.Generator, config: TrainingSceneConfig) -> tuple[list[Camera], list[dict]]:
    cameras, params = [], []
    for _ in range(config.views):
        fov = float(rng.uniform(*config.fov_deg))
        elevation = float(rng.uniform(*config.elevation_deg))
        azimuth = float(rng.uniform(0.0, 360.0))
        distance = distance_to_cover_sphere(1.0, fov)
        cameras.append(orbit_camera(azimuth, elevation, distance, config.size, config.size, fov, axis="min"))
        params.append({"azimuth_deg": azimuth, "elevation_deg": elevation, "fov_deg": fov})
    return cameras, params


def auto_exposure_ev(environment: Environment) -> float:
    """EV that brings the environment's solid-angle-weighted mean luminance to 1 (the built-in
    environments' normalisation, under which a white diffuse surface facing up renders at ~1)."""
    h = environment.height
    weights = np.cos((np.arange(h) + 0.5) / h * np.pi - np.pi / 2.0)[:, None]
    rgb = environment.radiance.astype(np.float64)
    luminance = rgb @ LUMINANCE_WEIGHTS
    mean = float((luminance * weights).sum() / (weights.sum() * environment.width))
    return float(-np.log2(max(mean, 1e-8)))


def make_training_scene(renderer: PBRRenderer, seed: int, config: TrainingSceneConfig = TrainingSceneConfig(),
                        environments: dict[str, Environment] | None = None) -> TrainingScene:
    """The scene of `seed`. `environments` may hold already-loaded environments by name (a cache)."""
    rng = np.random.default_rng([GENERATOR_VERSION, seed])
    object_name = str(rng.choice(config.objects))
    variant = int(rng.integers(0, 2**31 - 1))
    turn = float(rng.uniform(0.0, 360.0))
    radius = float(rng.uniform(*config.object_radius))
    env_name = str(rng.choice(config.environments))
    env_rotation = float(rng.uniform(0.0, 360.0))
    tint = rng.uniform(1.0 - config.white_balance, 1.0 + config.white_balance, 3)
    tint = tint / (tint @ LUMINANCE_WEIGHTS)  # a colour shift, not a brightness change
    # Both drawn every time, so the specular copy of a seed differs from the original only in roughness.
    specular = bool(rng.uniform() < config.specular_copy_probability)
    specular_scale = float(rng.uniform(*config.specular_roughness_scale))
    roughness_scale = specular_scale if specular else 1.0
    cameras, camera_params = sample_cameras(rng, config)

    model = resolve_asset(object_name, seed=variant)
    meshes = model.meshes if roughness_scale == 1.0 else [_with_roughness_scaled(m, roughness_scale) for m in model.meshes]
    transform = normalizing_transform(model.bounds)
    c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
    turn_z = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    transform = turn_z @ transform
    transform[:3] *= radius

    environment = (environments or {}).get(env_name) or resolve_environment(env_name, width=config.environment_width)
    tinted = Environment(environment.radiance * tint.astype(np.float32), name=f"{environment.name}*tint")
    exposure = auto_exposure_ev(environment)
    lighting = renderer.prepare_lighting(tinted, rotation_deg=env_rotation)
    try:
        views = render_meshes(renderer, lighting, meshes, transform, cameras, config.supersample, exposure_ev=exposure)
    finally:
        lighting.maps.release()
    description = SceneDescription(seed, object_name, variant, turn, radius, env_name, env_rotation, exposure,
                                   tuple(float(t) for t in tint), roughness_scale, camera_params)
    return TrainingScene(description, views)


def _with_roughness_scaled(mesh: MeshData, scale: float) -> MeshData:
    """A shallow copy sharing the geometry and textures, with its own scaled material (glTF's
    roughness is factor x texture, so scaling the factor scales every texel)."""
    scaled = copy.copy(mesh)
    scaled.material = copy.copy(mesh.material)
    scaled.material.roughness_factor = float(mesh.material.roughness_factor) * scale
    return scaled
