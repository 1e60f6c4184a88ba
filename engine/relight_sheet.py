"""A contact sheet of assets relit: one row per (asset, environment), one column per orbit view.

Used by `lirm demo` to put the exported asset next to the original object under environments the
photos were not taken in, which is the product's promise (a relightable asset), checked by eye.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lirm.renderer.environment import Environment
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings

from .assets.model_loader import LoadedModel
from .io.images import to_uint8, write_png
from .orbit_render import OrbitRenderConfig, normalizing_transform, orbit_for


def relit_sheet(renderer: PBRRenderer, assets: list[tuple[str, LoadedModel]], environments: dict[str, Environment],
                path: Path, views: int = 4, size: int = 192, elevation_deg: float = 20.0) -> tuple[Path, list[str]]:
    """Renders every asset (scaled into the unit sphere) under every environment from `views`
    azimuths; returns the sheet's path and its row labels ("asset under environment"), top to bottom."""
    cameras = orbit_for(OrbitRenderConfig(views=views, width=size, height=size, elevation_deg=elevation_deg,
                                          start_azimuth_deg=-35.0))
    rows, labels = [], []
    lightings = {name: renderer.prepare_lighting(env) for name, env in environments.items()}
    try:
        for env_name, lighting in lightings.items():
            for label, model in assets:
                scene = renderer.upload(model.meshes, normalizing_transform(model.bounds))
                try:
                    row = [to_uint8(renderer.render_view(scene, camera, lighting, RenderSettings(supersample=2)).beauty)
                           for camera in cameras]
                finally:
                    scene.release()
                rows.append(np.concatenate(row, axis=1))
                labels.append(f"{label} under {env_name}")
    finally:
        for lighting in lightings.values():
            lighting.maps.release()
    return write_png(path, np.concatenate(rows, axis=0)), labels
