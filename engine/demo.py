"""`lirm demo`: the main job on built-in data only (nothing to download).

For now (issue 2) it renders the built-in procedural objects under the built-in environments:
full orbits with every G-buffer channel for one object, and an overview sheet of all of them.
Later issues grow this into the whole pipeline (capture, reconstruction, export).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from lirm.renderer.context import create_headless_context
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS, make_procedural_environment

from .assets.asset_source import resolve_asset
from .io.images import to_uint8, write_png
from .orbit_render import OrbitRenderConfig, normalizing_transform, orbit_for, render_orbit
from .synth.procedural_objects import BUILTIN_OBJECTS


@dataclass
class DemoConfig:
    orbit_object: str = BUILTIN_OBJECTS[0]
    orbit: OrbitRenderConfig = field(default_factory=lambda: OrbitRenderConfig(views=8, width=512, height=512))
    overview_size: int = 256
    environment_width: int = 1024


@dataclass
class DemoResult:
    out_dir: Path
    orbit_dirs: dict[str, Path]
    overview: Path


def run_demo(out_dir: str | Path, config: DemoConfig = DemoConfig(), progress: Callable[[str], None] | None = None) -> DemoResult:
    out_dir = Path(out_dir)
    say = progress or (lambda message: None)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        environments = {name: make_procedural_environment(name, width=config.environment_width) for name in PROCEDURAL_ENVIRONMENTS}
        orbit_dirs = {}
        model = resolve_asset(config.orbit_object)
        for env_name, env in environments.items():
            target = out_dir / config.orbit_object / env_name
            say(f"rendering {config.orbit.views} views of '{config.orbit_object}' under '{env_name}'")
            render_orbit(renderer, model, env, config.orbit, target)
            orbit_dirs[env_name] = target
        say(f"rendering the overview of {len(BUILTIN_OBJECTS)} objects x {len(environments)} environments")
        overview = _overview(renderer, environments, config, out_dir / "overview.png")
        return DemoResult(out_dir, orbit_dirs, overview)
    finally:
        renderer.release()
        ctx.release()


def _overview(renderer: PBRRenderer, environments: dict, config: DemoConfig, path: Path) -> Path:
    """One three-quarter view per object (rows) and environment (columns)."""
    s = config.overview_size
    view = replace(config.orbit, views=1, width=s, height=s, start_azimuth_deg=-35.0)
    camera = orbit_for(view)[0]
    sheet = np.zeros((s * len(BUILTIN_OBJECTS), s * len(environments), 3), np.uint8)
    lightings = [renderer.prepare_lighting(env) for env in environments.values()]
    try:
        for row, name in enumerate(BUILTIN_OBJECTS):
            model = resolve_asset(name)
            scene = renderer.upload(model.meshes, normalizing_transform(model.bounds))
            try:
                for col, lighting in enumerate(lightings):
                    out = renderer.render_view(scene, camera, lighting, RenderSettings(supersample=2))
                    sheet[row * s:(row + 1) * s, col * s:(col + 1) * s] = to_uint8(out.beauty)
            finally:
                scene.release()
    finally:
        for lighting in lightings:
            lighting.maps.release()
    return write_png(path, sheet)
