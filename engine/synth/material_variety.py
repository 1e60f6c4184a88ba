"""Scenes of varied materials and shapes, for the image-space material prior (model/material_net.py).

The LIRM prior's training scenes (training_scenes.py) are the four built-in kinds, each of which
carries some metal (a gold rim, a brass band, a brushed base) on a mostly dielectric body, under the
three built-in environments. A network that learns materials from them alone may learn that every
object has metal somewhere and that grey means silver: on the glTF set's inputs it sees metal on a
plain white bunny and none on an all-metal monkey. These scenes are meant to break those correlations:

- shapes: the built-in objects' geometry half the time, otherwise a smooth random blob (a sphere
  displaced by a few low-frequency waves and stretched) or a torus;
- materials: a built-in object keeps its own paint (a third of the time), loses its metal (the same
  paint, all dielectric), or is repainted one random material per part; a blob or torus is cut by
  random planes into one to three parts, each of one random material. A random material is metal a
  third of the time (a metal's colour, smooth to middling), otherwise a dielectric whose colour is
  as often a grey (white to black) as a hue, smooth to rough;
- lighting: each built-in environment re-rigged by its own `randomized` (sun, boxes, sky colours),
  rotated and tinted.

Every scene is fully determined by its seed. Nothing here is drawn by the LIRM prior's generator.

Measured (stop 81; README, "Varied scenes"): 500 of them beside the 500 training scenes, at the same
training length, left the network unsure everywhere (on the held-out synthetic inputs metallic 23.5 ->
15.8 dB) and hardly surer on the glTF set (6.9 against 7.4): under the built-in skies, which have no
detail to reflect, a smooth metal blob and a pale paint look alike, and the network learns to hedge.
`lirm train-materials --varied-scenes N` keeps them to hand (0 by default).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import trimesh

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.cameras import Camera
from lirm.engine.orbit_render import normalizing_transform
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.mesh import MeshData, compute_vertex_normals
from lirm.renderer.pbr_renderer import PBRRenderer
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS, PROCEDURAL_ENVIRONMENTS

from .object_views import ObjectViews, render_meshes
from .procedural_objects import BUILTIN_OBJECTS, METALS
from .training_scenes import TrainingSceneConfig, auto_exposure_ev, sample_cameras

VARIETY_VERSION = 1  # bump when a change would alter the scene a seed produces

# Linear base colours of metals (physically based tables, rounded), beside the built-in objects' own.
# The built-in objects' metals are display (sRGB) colours for their textures; a base colour factor is linear.
METAL_COLOURS = tuple((np.asarray(c, np.float32) ** 2.2).astype(np.float32) for c in METALS.values()) + (
    np.array([0.56, 0.57, 0.58], np.float32),  # iron
    np.array([0.91, 0.92, 0.92], np.float32),  # aluminium
    np.array([0.66, 0.61, 0.53], np.float32),  # nickel-ish pewter
)


@dataclass(frozen=True)
class VarietyConfig:
    builtin_shape_probability: float = 0.5
    torus_probability: float = 0.2  # of the shapes that are not built-in
    keep_paint_probability: float = 1 / 3  # of the built-in shapes; the rest split evenly: metal removed, repainted
    metal_probability: float = 1 / 3  # a random material is metal
    grey_probability: float = 0.5  # a random dielectric is a grey rather than a hue
    parts: tuple[float, float, float] = (0.45, 0.35, 0.20)  # a blob's chance of 1, 2 or 3 parts
    blob_waves: int = 4
    blob_amplitude: float = 0.28  # total, in units of the sphere's radius
    white_balance: float = 0.1


@dataclass
class VariedScene:
    seed: int
    shape: str  # "vase", ..., "blob" or "torus"
    paint: str  # "own", "no metal", "repainted" or "parts"
    environment: str
    views: ObjectViews


def random_material(rng: np.random.Generator, config: VarietyConfig, name: str) -> PBRMaterial:
    """One uniform glTF material: a metal, a grey dielectric or a coloured one."""
    if rng.uniform() < config.metal_probability:
        colour = METAL_COLOURS[rng.integers(len(METAL_COLOURS))] * rng.uniform(0.85, 1.05, 3)
        roughness, metallic = float(rng.uniform(0.0, 1.0) ** 2 * 0.6 + 0.03), 1.0  # mostly smooth
    else:
        if rng.uniform() < config.grey_probability:
            colour = np.full(3, rng.uniform(0.02, 0.9), np.float32) * rng.uniform(0.97, 1.03, 3)
        else:
            hue = rng.uniform(0.0, 1.0)
            saturation, value = rng.uniform(0.2, 1.0), rng.uniform(0.1, 0.9)
            colour = _hsv_to_linear_rgb(hue, saturation, value)
        roughness, metallic = float(rng.uniform(0.05, 0.95)), 0.0
    colour = np.clip(colour, 0.0, 1.0)
    return PBRMaterial(name=name, base_color_factor=(*map(float, colour), 1.0), metallic_factor=metallic,
                       roughness_factor=roughness)


def _hsv_to_linear_rgb(h: float, s: float, v: float) -> np.ndarray:
    k = (np.array([5.0, 3.0, 1.0]) + h * 6.0) % 6.0
    srgb = v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return (srgb ** 2.2).astype(np.float32)  # display colour picked, stored linear as glTF's factor is


def blob_geometry(rng: np.random.Generator, config: VarietyConfig) -> tuple[np.ndarray, np.ndarray]:
    """A smooth closed random shape: a sphere displaced along its normals by a few waves, then stretched."""
    sphere = trimesh.creation.icosphere(subdivisions=4)
    p = np.asarray(sphere.vertices, np.float64)
    radius = np.ones(len(p))
    amplitudes = rng.dirichlet(np.ones(config.blob_waves)) * config.blob_amplitude
    for a in amplitudes:
        direction = rng.normal(size=3)
        direction *= rng.uniform(1.0, 3.5) / np.linalg.norm(direction)
        radius += a * np.sin(p @ direction + rng.uniform(0.0, 2 * np.pi))
    p = p * radius[:, None] * rng.uniform(0.6, 1.2, 3)
    return p.astype(np.float32), np.asarray(sphere.faces, np.int64)


def torus_geometry(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=float(rng.uniform(0.2, 0.5)),
                                   major_sections=64, minor_sections=32)
    tilt = trimesh.transformations.rotation_matrix(float(rng.uniform(0.0, np.pi)), rng.normal(size=3))[:3, :3]
    return (np.asarray(torus.vertices) @ tilt.T).astype(np.float32), np.asarray(torus.faces, np.int64)


def split_into_parts(positions: np.ndarray, faces: np.ndarray, count: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Face index lists of up to `count` parts cut by random planes near the centre (empty parts dropped)."""
    centroids = positions[faces].mean(1)
    centre = positions.mean(0)
    label = np.zeros(len(faces), np.int64)
    for _ in range(count - 1):
        normal = rng.normal(size=3)
        normal /= np.linalg.norm(normal)
        offset = rng.uniform(-0.3, 0.3) * np.abs((positions - centre) @ normal).max()
        label += ((centroids - centre) @ normal > offset).astype(np.int64)
    return [faces[label == k] for k in range(count) if (label == k).any()]


def _parts_meshes(positions: np.ndarray, faces: np.ndarray, materials: list[PBRMaterial], parts: list[np.ndarray],
                  shape: str) -> list[MeshData]:
    # Normals from the whole surface, so that the cuts leave no shading seam.
    normals = compute_vertex_normals(positions, faces.astype(np.uint32))
    return [MeshData(positions, part.astype(np.uint32), normals=normals, material=mat, name=f"{shape}/part{k}")
            for k, (part, mat) in enumerate(zip(parts, materials))]


def varied_meshes(rng: np.random.Generator, config: VarietyConfig) -> tuple[list[MeshData], str, str]:
    """The scene's meshes, its shape's name and how it was painted."""
    if rng.uniform() < config.builtin_shape_probability:
        shape = str(rng.choice(BUILTIN_OBJECTS))
        meshes = resolve_asset(shape, seed=int(rng.integers(0, 2**31 - 1))).meshes
        pick = rng.uniform()
        if pick < config.keep_paint_probability:
            return meshes, shape, "own"
        out = []
        for mesh in meshes:
            painted = copy.copy(mesh)
            if pick < (1.0 + config.keep_paint_probability) / 2.0:
                painted.material = copy.copy(mesh.material)
                painted.material.metallic_factor = 0.0  # glTF metal is factor x texture: none anywhere
            else:
                painted.material = random_material(rng, config, f"{mesh.name}/repainted")
                painted.material.normal_texture, painted.material.normal_scale = mesh.material.normal_texture, mesh.material.normal_scale
            out.append(painted)
        return out, shape, "no metal" if pick < (1.0 + config.keep_paint_probability) / 2.0 else "repainted"
    if rng.uniform() < config.torus_probability:
        shape, (positions, faces) = "torus", torus_geometry(rng)
    else:
        shape, (positions, faces) = "blob", blob_geometry(rng, config)
    count = int(rng.choice(len(config.parts), p=np.asarray(config.parts) / sum(config.parts))) + 1
    parts = split_into_parts(positions, faces, count, rng)
    materials = [random_material(rng, config, f"{shape}/material{k}") for k in range(len(parts))]
    return _parts_meshes(positions, faces, materials, parts, shape), shape, "parts"


def make_varied_scene(renderer: PBRRenderer, seed: int, scene: TrainingSceneConfig,
                      config: VarietyConfig = VarietyConfig()) -> VariedScene:
    """The varied scene of `seed`: its cameras drawn as the training scenes' are (scene.views, size, fov)."""
    rng = np.random.default_rng([VARIETY_VERSION, seed])
    meshes, shape, paint = varied_meshes(rng, config)
    env_name = str(rng.choice(tuple(PROCEDURAL_ENVIRONMENTS)))
    environment = PROCEDURAL_ENVIRONMENTS[env_name].randomized(rng).render(scene.environment_width)
    tint = rng.uniform(1.0 - config.white_balance, 1.0 + config.white_balance, 3)
    tint = tint / (tint @ LUMINANCE_WEIGHTS)
    tinted = Environment(environment.radiance * tint.astype(np.float32), name=f"{env_name}*varied")
    cameras: list[Camera] = sample_cameras(rng, scene)[0]
    bounds = np.stack([np.min([m.positions[np.unique(m.indices)].min(0) for m in meshes], 0),
                       np.max([m.positions[np.unique(m.indices)].max(0) for m in meshes], 0)])
    transform = normalizing_transform(bounds)
    transform[:3] *= float(rng.uniform(*scene.object_radius))
    lighting = renderer.prepare_lighting(tinted, rotation_deg=float(rng.uniform(0.0, 360.0)))
    try:
        views = render_meshes(renderer, lighting, meshes, transform, cameras, scene.supersample,
                              exposure_ev=auto_exposure_ev(environment))
    finally:
        lighting.maps.release()
    return VariedScene(seed, shape, paint, env_name, views)
