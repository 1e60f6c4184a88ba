"""Image-based lighting maps computed on the GPU (compute shaders, OpenGL 4.3).

An Environment (equirectangular radiance) becomes:
- an environment cube map with a full mip chain (background and the source of the filters),
- a GGX-prefiltered specular cube whose mip level k holds perceptual roughness k / (levels - 1),
- a diffuse irradiance cube in radiance units (E / pi),
and, once per context, the split-sum BRDF lookup table. Rotation about +Z and exposure are applied
at lookup time by the shaders, so changing them never re-runs these filters.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import moderngl
import numpy as np

from .context import make_current
from .environment import Environment
from .shader_source import shader_source

RGBA16F = 0x881A  # GL_RGBA16F: 16-bit floats keep HDR range (up to 65504) at half the memory of 32-bit


@dataclass(frozen=True)
class IBLConfig:
    cube_size: int | None = None  # environment cube face size; None = panorama width / 4 (no detail lost)
    max_cube_size: int = 512
    specular_levels: int = 6  # roughness 0, 0.2, ..., 1
    specular_samples: int = 128
    irradiance_size: int = 64  # 32 leaves visible interpolation error where a bright light grazes the horizon
    # Rows of the area-averaged panorama that the irradiance integrates (2x as many columns). The
    # cosine lobe is smooth, so 64 x 128 bins (2.8 degrees) lose nothing visible, and averaging
    # (not point sampling) keeps the energy of small bright lights exactly.
    irradiance_source_height: int = 32
    irradiance_bright_texels: int = 2048  # kept exact (see irradiance_sources)
    lut_size: int = 128
    lut_samples: int = 512

    # llvmpipe (Mesa 22) returns wrong irradiance sums beyond ~70k sources in one dispatch
    # (measured: 67,712 right, 73,728 wrong); the presets stay far below.
    MAX_IRRADIANCE_SOURCES = 65536

    def __post_init__(self) -> None:
        sources = 2 * self.irradiance_source_height**2 + self.irradiance_bright_texels
        if sources > self.MAX_IRRADIANCE_SOURCES:
            raise ValueError(f"{sources} irradiance sources exceed {self.MAX_IRRADIANCE_SOURCES}; lower irradiance_source_height")
        if self.specular_levels < 2 or self.specular_samples < 1 or self.irradiance_size < 4:
            raise ValueError("IBLConfig needs at least 2 specular levels, 1 sample and a 4x4 irradiance cube")


IBL_PRESETS = {
    "default": IBLConfig(),
    "preview": IBLConfig(max_cube_size=256, specular_samples=64, irradiance_size=32, irradiance_bright_texels=1024),
    "high": IBLConfig(max_cube_size=1024, specular_samples=512, irradiance_source_height=128),
}


@dataclass
class IBLMaps:
    environment_cube: moderngl.TextureCube
    specular_cube: moderngl.TextureCube
    irradiance_cube: moderngl.TextureCube
    specular_levels: int
    name: str
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage (GPU-synchronised)

    def release(self) -> None:
        for tex in (self.environment_cube, self.specular_cube, self.irradiance_cube):
            tex.release()


class IBLBaker:
    """Owns the compute programs and the BRDF table for one GL context."""

    def __init__(self, ctx: moderngl.Context, config: IBLConfig = IBLConfig()):
        make_current(ctx)
        self.ctx = ctx
        self.config = config
        self._to_cube = ctx.compute_shader(shader_source("equirect_to_cube.comp"))
        self._prefilter = ctx.compute_shader(shader_source("prefilter_specular.comp"))
        self._irradiance = ctx.compute_shader(shader_source("irradiance.comp"))
        self._brdf_lut: moderngl.Texture | None = None

    @property
    def brdf_lut(self) -> moderngl.Texture:
        make_current(self.ctx)
        if self._brdf_lut is None:
            self._brdf_lut = self._compute_brdf_lut()
        return self._brdf_lut

    def _compute_brdf_lut(self) -> moderngl.Texture:
        size = self.config.lut_size
        lut = self.ctx.texture((size, size), 2, dtype="f4")
        lut.filter = (moderngl.LINEAR, moderngl.LINEAR)
        lut.repeat_x = lut.repeat_y = False
        program = self.ctx.compute_shader(shader_source("brdf_lut.comp"))
        program["u_size"] = size
        program["u_samples"] = self.config.lut_samples
        lut.bind_to_image(0, read=False, write=True)
        program.run(_groups(size), _groups(size), 1)
        self.ctx.finish()
        program.release()
        return lut

    def bake(self, environment: Environment) -> IBLMaps:
        make_current(self.ctx)
        cfg = self.config
        ctx = self.ctx
        timings: dict[str, float] = {}
        t0 = time.perf_counter()

        equirect = ctx.texture((environment.width, environment.height), 3, environment.radiance.tobytes(), dtype="f4")
        equirect.filter = (moderngl.LINEAR, moderngl.LINEAR)
        equirect.repeat_x = True
        equirect.repeat_y = False
        size = cfg.cube_size or _power_of_two_at_most(max(environment.width // 4, 16), cfg.max_cube_size)
        env_cube = self._cube(size, mipmaps=True)
        self._to_cube["u_equirect"] = 0
        self._to_cube["u_size"] = size
        # Enough sub-samples that every equirect texel under a cube texel is read at least once.
        self._to_cube["u_supersample"] = int(max(1, min(4, np.ceil(environment.width / (4.0 * size)))))
        equirect.use(0)
        env_cube.bind_to_image(0, read=False, write=True, level=0)
        self._to_cube.run(_groups(size), _groups(size), 6)
        ctx.finish()
        env_cube.build_mipmaps()
        ctx.finish()
        equirect.release()
        timings["equirect_to_cube"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        levels = min(cfg.specular_levels, int(np.log2(size)) + 1)
        specular = self._cube(size, mipmaps=True)
        env_cube.use(0)
        self._prefilter["u_source"] = 0
        self._prefilter["u_source_size"] = size
        self._prefilter["u_samples"] = cfg.specular_samples
        for level in range(levels):
            level_size = max(size >> level, 1)
            self._prefilter["u_size"] = level_size
            self._prefilter["u_roughness"] = level / max(levels - 1, 1)
            specular.bind_to_image(0, read=False, write=True, level=level)
            self._prefilter.run(_groups(level_size), _groups(level_size), 6)
        ctx.finish()
        # Levels past the last roughness stay as glGenerateMipmap left them; clamp lookups to `levels`.
        specular.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        timings["specular_prefilter"] = time.perf_counter() - t0

        t0 = time.perf_counter()
        sources = irradiance_sources(environment, cfg.irradiance_source_height, cfg.irradiance_bright_texels)
        source_buffer = ctx.buffer(sources.tobytes())
        source_buffer.bind_to_storage_buffer(0)
        irradiance = self._cube(cfg.irradiance_size, mipmaps=False)
        self._irradiance["u_size"] = cfg.irradiance_size
        self._irradiance["u_source_count"] = len(sources)
        irradiance.bind_to_image(0, read=False, write=True, level=0)
        self._irradiance.run(_groups(cfg.irradiance_size), _groups(cfg.irradiance_size), 6)
        ctx.finish()
        source_buffer.release()
        timings["irradiance"] = time.perf_counter() - t0

        _ = self.brdf_lut  # computed once per context, timed separately by the benchmark
        return IBLMaps(env_cube, specular, irradiance, levels, environment.name, timings)

    def _cube(self, size: int, mipmaps: bool) -> moderngl.TextureCube:
        tex = self.ctx.texture_cube((size, size), 4, dtype="f2", internal_format=RGBA16F)
        if mipmaps:
            tex.build_mipmaps()  # allocates the chain that the compute passes write into
            tex.filter = (moderngl.LINEAR_MIPMAP_LINEAR, moderngl.LINEAR)
        else:
            tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        return tex

    def release(self) -> None:
        for prog in (self._to_cube, self._prefilter, self._irradiance):
            prog.release()
        if self._brdf_lut is not None:
            self._brdf_lut.release()


def irradiance_sources(environment: Environment, height: int, bright_texels: int) -> np.ndarray:
    """Point sources whose cosine-weighted sum is the irradiance: (N, 8) float32 rows of
    (direction xyz, solid angle, radiance rgb, 0).

    The `bright_texels` most powerful texels stay individual sources at full resolution (a small
    light near a normal's horizon must switch off where it really does); the rest of the panorama is
    averaged into height x 2*height bins weighted by solid angle, which keeps its energy exactly.
    """
    h, w = environment.height, environment.width
    height = min(height, h)
    width = min(2 * height, w)
    dirs, solid_angle = environment.texel_directions()
    dirs = dirs.reshape(-1, 3)
    sa = solid_angle.ravel()
    radiance = environment.radiance.reshape(-1, 3).astype(np.float64)
    power = (radiance @ np.array([0.2126, 0.7152, 0.0722])) * sa
    k = min(bright_texels, power.size)
    bright = np.argpartition(power, power.size - k)[power.size - k:] if k else np.zeros(0, np.int64)
    dim_radiance = radiance.copy()
    dim_radiance[bright] = 0.0

    bin_row = (np.arange(h) * height) // h
    bin_col = (np.arange(w) * width) // w
    bins = (bin_row[:, None] * width + bin_col[None, :]).ravel()
    count = height * width

    def binned(values: np.ndarray) -> np.ndarray:
        return np.stack([np.bincount(bins, weights=values[:, c] * sa, minlength=count) for c in range(values.shape[1])], 1)

    total = np.bincount(bins, weights=sa, minlength=count)
    mean_direction = binned(dirs)
    mean_direction /= np.linalg.norm(mean_direction, axis=1, keepdims=True)
    out = np.zeros((count + k, 8), np.float32)
    out[:count, :3] = mean_direction
    out[:count, 3] = total
    out[:count, 4:7] = binned(dim_radiance) / total[:, None]
    out[count:, :3] = dirs[bright]
    out[count:, 3] = sa[bright]
    out[count:, 4:7] = radiance[bright]
    return out


def sample_cube(ctx: moderngl.Context, cube: moderngl.TextureCube, directions: np.ndarray, lod: float = 0.0) -> np.ndarray:
    """Read a cube map at world directions (N, 3) and one mip level; returns (N, 4) float32."""
    directions = np.asarray(directions, dtype=np.float32).reshape(-1, 3)
    n = len(directions)
    queries = np.concatenate([directions, np.full((n, 1), lod, np.float32)], axis=1)
    program = ctx.compute_shader(shader_source("sample_cube.comp"))
    q = ctx.buffer(queries.tobytes())
    out = ctx.buffer(reserve=n * 16)
    q.bind_to_storage_buffer(0)
    out.bind_to_storage_buffer(1)
    cube.use(0)
    program["u_cube"] = 0
    program["u_count"] = n
    program.run((n + 63) // 64)
    result = np.frombuffer(out.read(), dtype=np.float32).reshape(n, 4).copy()
    for obj in (program, q, out):
        obj.release()
    return result


def _groups(size: int, local: int = 8) -> int:
    return (size + local - 1) // local


def _power_of_two_at_most(value: int, cap: int) -> int:
    p = 1
    while p * 2 <= min(value, cap):
        p *= 2
    return p
