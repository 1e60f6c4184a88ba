"""The renderer's prefiltered lighting read back from the GPU as torch tables (split_sum_shading.py).

The specular and irradiance cubes are sampled at the texel centres of equirectangular grids, each
level at about the cube level's own resolution (4 x face size wide), so nothing the cube holds is
lost and the torch shading matches the OpenGL shading it is the twin of.
"""

from __future__ import annotations

import numpy as np
import torch

from lirm.renderer.environment import Environment, rotation_about_z
from lirm.renderer.ibl import sample_cube
from lirm.renderer.pbr_renderer import Lighting, PBRRenderer

from .split_sum_shading import SplitSumTables


def equirect_directions(width: int) -> np.ndarray:
    """(width / 2, width, 3) unit directions of an equirectangular grid's texel centres."""
    return Environment(np.zeros((width // 2, width, 3), np.float32)).texel_directions()[0].astype(np.float32)


def tables_from_lighting(renderer: PBRRenderer, lighting: Lighting, max_width: int = 1024) -> SplitSumTables:
    maps = lighting.maps
    ctx = renderer.ctx
    face = maps.specular_cube.size[0]
    specular = []
    for level in range(maps.specular_levels):
        width = int(min(max(8 * (face >> level), 16), max_width))
        dirs = equirect_directions(width)
        values = sample_cube(ctx, maps.specular_cube, dirs.reshape(-1, 3), lod=float(level))[:, :3]
        specular.append(torch.from_numpy(values.reshape(width // 2, width, 3).copy()))
    width = int(min(4 * maps.irradiance_cube.size[0], max_width))
    dirs = equirect_directions(width)
    irradiance = sample_cube(ctx, maps.irradiance_cube, dirs.reshape(-1, 3), lod=0.0)[:, :3].reshape(width // 2, width, 3)
    lut = renderer.baker.brdf_lut
    size = lut.size[0]
    table = np.frombuffer(lut.read(), dtype=np.float32).reshape(size, size, 2)  # GL row 0 = roughness 0
    rotation = rotation_about_z(-lighting.rotation_deg)  # world -> environment, as the renderer binds it
    return SplitSumTables(specular, torch.from_numpy(irradiance.copy()), torch.from_numpy(table.copy()),
                          torch.from_numpy(rotation.astype(np.float32)), float(2.0**lighting.intensity_ev))
