"""The held-out evaluation sets, rendered with the supplementary's test protocol.

- synthetic: built-in procedural objects whose variants come from seeds training never draws
  (training draws variants below 2^31; these are 2^31 + i), under the built-in environments,
  randomly rotated; fixed by the set's seed.
- gltf: the glTF models of a folder (../shared/data/pbr_models) under the HDRIs of another
  (../shared/data/envmaps), one environment per model in turn.

Every object is also rendered from its output views under a second environment that lit none of its
inputs (the next one in turn, randomly rotated): the truth of the relighting test (relighting.py).
Each object names both (`lit_by`, `relight.name`), and the report prints them.

Each object: 48 protocol cameras (elevations 0/20/40 x 16 azimuths, FoV 50, the bounding sphere
just fitting), the seeded input sets and output views, ground-truth maps, and points on the true
surface for the Chamfer distance. Inputs are cut as the capture pipeline cuts photos, the same
framing the network is trained on.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lirm.engine.assets.asset_source import resolve_asset
from lirm.engine.assets.environment_files import resolve_environment
from lirm.engine.assets.model_loader import LoadedModel
from lirm.engine.orbit_render import normalizing_transform
from lirm.engine.synth.evaluation_protocol import ProtocolConfig, ProtocolViews, protocol_views
from lirm.engine.synth.object_views import ObjectViews, render_meshes
from lirm.engine.synth.procedural_objects import BUILTIN_OBJECTS
from lirm.engine.synth.training_scenes import auto_exposure_ev
from lirm.renderer.pbr_renderer import PBRRenderer
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS

from .chamfer import surface_samples
from .relighting import PICTURE_VIEWS, RelightTruth, render_relight_truth

HELDOUT_VARIANT_BASE = 2**31  # training's object variants are drawn from [0, 2^31 - 1)
OBJECT_RADIUS = 0.8


@dataclass
class HeldoutObject:
    name: str
    protocol: ProtocolViews
    views: ObjectViews  # all 48 protocol views, full frame
    surface: np.ndarray | None  # (N, 3) points on the true surface, in the field's frame (None: unknown)
    inputs_prepared: bool = False  # the views are already the capture's crops (a real capture)
    mesh: tuple[np.ndarray, np.ndarray] | None = None  # the true surface as (vertices, faces), when known
    lit_by: str = ""  # the environment (and rotation) the input and output views were rendered under
    relight: RelightTruth | None = None  # the output views under an environment that lit none of the inputs
    # The first few output views under a third environment, for the relighting pictures only (not scored).
    relight_also: RelightTruth | None = None
    # The light of the inputs themselves, (environment, rotation_deg, exposure_ev), where known: for the
    # bench's oracle runs (`lirm bench refine --lighting truth`), never for a method under test.
    input_light: tuple | None = None


def _render_object(renderer: PBRRenderer, name: str, model: LoadedModel, environment, rotation_deg: float, turn_deg: float,
                   protocol: ProtocolViews, surface_points: int, seed: int, relight_environment=None,
                   relight_rotation_deg: float = 0.0, picture_environment=None, picture_rotation_deg: float = 0.0,
                   relight_gbuffers: bool = False) -> HeldoutObject:
    meshes = model.meshes
    transform = normalizing_transform(model.bounds)
    c, s = np.cos(np.radians(turn_deg)), np.sin(np.radians(turn_deg))
    transform = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]) @ transform
    transform[:3] *= OBJECT_RADIUS
    lighting = renderer.prepare_lighting(environment, rotation_deg=rotation_deg)
    try:
        views = render_meshes(renderer, lighting, meshes, transform, protocol.cameras, supersample=2,
                              exposure_ev=auto_exposure_ev(environment))
    finally:
        lighting.maps.release()
    vertices, faces, offset = [], [], 0
    for m in meshes:
        p = np.c_[m.positions, np.ones(len(m.positions))] @ transform.T
        vertices.append(p[:, :3])
        faces.append(m.indices.astype(np.int64) + offset)
        offset += len(m.positions)
    vertices, faces = np.concatenate(vertices).astype(np.float32), np.concatenate(faces)
    surface = surface_samples(vertices, faces, surface_points, seed)
    relight = None
    if relight_environment is not None:
        relight = render_relight_truth(renderer, meshes, transform, protocol.cameras, list(protocol.outputs), relight_environment,
                                       relight_rotation_deg, auto_exposure_ev(relight_environment), relight_gbuffers)
    relight_also = None
    if picture_environment is not None:
        relight_also = render_relight_truth(renderer, meshes, transform, protocol.cameras, list(protocol.outputs)[:PICTURE_VIEWS],
                                            picture_environment, picture_rotation_deg, auto_exposure_ev(picture_environment))
    return HeldoutObject(name, protocol, views, surface, mesh=(vertices, faces),
                         lit_by=f"{environment.name} (rotated {rotation_deg:.0f}°)", relight=relight, relight_also=relight_also,
                         input_light=(environment, rotation_deg, auto_exposure_ev(environment)))


def synthetic_heldout(renderer: PBRRenderer, count: int = 8, size: int = 128, seed: int = 0,
                      surface_points: int = 20_000, relight_gbuffers: bool = False, first: int = 0) -> list[HeldoutObject]:
    """Objects `first` .. `first + count - 1` of the set; `relight_gbuffers`: keep the relighting truth's
    G-buffers (the swap study). Every object is the same whatever `first` (the set's draws are made for
    the objects before it too), so objects beyond the ones a setting was chosen on can be scored alone."""
    if first < 0:
        raise ValueError(f"the first object's index must be at least 0, got {first}")
    config = ProtocolConfig(size=size, seed=seed)
    rng = np.random.default_rng([seed, 2024])
    environments = list(PROCEDURAL_ENVIRONMENTS)
    objects = []
    for i in range(first + count):
        name = BUILTIN_OBJECTS[i % len(BUILTIN_OBJECTS)]
        variant = HELDOUT_VARIANT_BASE + seed * 10_000 + i
        env_name = environments[i % len(environments)]
        rotation, turn = float(rng.uniform(0, 360)), float(rng.uniform(0, 360))
        if i < first:
            continue
        model = resolve_asset(name, seed=variant)
        env = resolve_environment(env_name, width=512)
        # Drawn after the set's original draws, so that adding the relighting changed no object.
        relight_rotation = float(np.random.default_rng([seed, 2025, i]).uniform(0, 360))
        relight_env = resolve_environment(environments[(i + 1) % len(environments)], width=512)
        # The pictures' second environment: the third built-in one, lighting none of the inputs either.
        picture_env = resolve_environment(environments[(i + 2) % len(environments)], width=512)
        picture_rotation = float(np.random.default_rng([seed, 2026, i]).uniform(0, 360))
        objects.append(_render_object(renderer, f"{name}#{i}", model, env, rotation, turn,
                                      protocol_views(config, i), surface_points, seed + i, relight_env, relight_rotation,
                                      picture_env, picture_rotation, relight_gbuffers))
    return objects


def gltf_heldout(renderer: PBRRenderer, models: list[Path], environments: list[Path], size: int = 128, seed: int = 0,
                 surface_points: int = 20_000, relight_gbuffers: bool = False) -> list[HeldoutObject]:
    config = ProtocolConfig(size=size, seed=seed)
    rng = np.random.default_rng([seed, 4202])
    objects = []
    for i, path in enumerate(models):
        env = resolve_environment(environments[i % len(environments)])
        model = resolve_asset(path)
        rotation = float(rng.uniform(0, 360))
        relight_env, relight_rotation, picture_env, picture_rotation = None, 0.0, None, 0.0
        if len(environments) > 1:  # relit by an HDRI that lit none of its inputs
            relight_env = resolve_environment(environments[(i + 1) % len(environments)])
            relight_rotation = float(np.random.default_rng([seed, 4203, i]).uniform(0, 360))
        if len(environments) > 2:  # and shown under a third one in the pictures
            picture_env = resolve_environment(environments[(i + 2) % len(environments)])
            picture_rotation = float(np.random.default_rng([seed, 4204, i]).uniform(0, 360))
        objects.append(_render_object(renderer, Path(path).stem, model, env, rotation, 0.0,
                                      protocol_views(config, i), surface_points, seed + i, relight_env, relight_rotation,
                                      picture_env, picture_rotation, relight_gbuffers))
    return objects


def capture_heldout(capture_dir: Path, views_per_set: int = 4, sets: int = 4) -> list[HeldoutObject]:
    """A real capture as a one-object set: every 4th prepared view is held out as an output (the
    photos are the only truth: no materials or surface), the rest are input sets in frame order."""
    from lirm.engine.capture.capture_folder import Capture
    from lirm.engine.errors import LirmUserError

    capture = Capture.open(capture_dir)
    prepared = [v for v in (capture.read_prepared(fid) for fid in sorted(capture.cameras)) if v is not None]
    if len(prepared) < 2:
        raise LirmUserError(f"{capture_dir}: {len(prepared)} prepared views; evaluation needs at least 2 "
                            f"(one input, one held out): add photos with `lirm capture --add`")
    outputs = list(range(3, len(prepared), 4)) or [len(prepared) - 1]
    inputs = [i for i in range(len(prepared)) if i not in outputs]
    input_sets = [inputs[k:k + views_per_set] for k in range(0, len(inputs), views_per_set)][:sets]
    protocol = ProtocolViews([v.camera for v in prepared], [], [], input_sets, outputs)
    views = ObjectViews([v.camera for v in prepared], np.stack([v.image_masked for v in prepared]),
                        np.stack([v.image_bg for v in prepared]), np.stack([v.mask for v in prepared]),
                        None, None, None, None)
    return [HeldoutObject(Path(capture_dir).name, protocol, views, None, inputs_prepared=True)]
