"""Physically based rendering of glTF-material meshes under image-based lighting, with a G-buffer.

One renderer per GL context. `render()` draws any list of OpenCV cameras offscreen and reads the
results back as numpy arrays; `draw_to_framebuffer()` shows the tone-mapped image in a window's
framebuffer (the app). Both run the same passes:
  1. background: the environment through each pixel (or black), coverage 0,
  2. meshes: split-sum IBL shading into linear HDR plus albedo, roughness, metallic, occlusion,
     world normal, camera depth and texture coordinates,
  3. tone mapping: exposure, ACES fit, sRGB.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import moderngl
import numpy as np

from .context import make_current
from .camera_matrices import gl_bytes, near_far_for_bounds, view_projection_matrix
from .environment import rotation_about_z
from .gpu_scene import GpuScene
from .ibl import IBLBaker, IBLConfig, IBLMaps
from .mesh import MeshData
from .shader_source import shader_source
from .tonemap import TONEMAPPERS

GBUFFER_ATTACHMENTS = ("radiance", "albedo", "material", "normal_depth", "uv")
DISPLAY_CHANNELS = ("beauty", "albedo", "roughness", "metallic", "normal")  # what a viewport can show


@dataclass
class Lighting:
    """An environment prepared for shading, with its interactive controls."""

    maps: IBLMaps
    rotation_deg: float = 0.0  # about +Z, counter-clockwise seen from above
    intensity_ev: float = 0.0  # scales the environment's radiance by 2^ev


@dataclass
class RenderSettings:
    exposure_ev: float = 0.0  # camera exposure, applied at tone mapping only
    tonemapper: str = "aces"  # "aces" or "linear"
    show_environment: bool = True  # environment as the background of the beauty image
    background_blur: float = 0.0  # mip level of the environment cube used for the backdrop
    multiple_scattering: bool = True  # Fdez-Aguera energy compensation for rough metals
    supersample: int = 1  # render at k x k the size and average: antialiased edges, fractional coverage
    clear_color: tuple[float, float, float] = (0.0, 0.0, 0.0)  # backdrop when show_environment is off

    def __post_init__(self) -> None:
        if self.tonemapper not in TONEMAPPERS:
            raise ValueError(f"unknown tone mapper {self.tonemapper!r}; choose one of {', '.join(TONEMAPPERS)}")
        if not 1 <= int(self.supersample) <= 4:
            raise ValueError("supersample must be 1, 2, 3 or 4")


@dataclass
class RenderOutput:
    """One view, rows top to bottom as in the OpenCV image. Empty pixels hold 0 in every G-buffer channel."""

    beauty: np.ndarray  # (H, W, 3) float32 display sRGB in [0, 1], tone mapped
    radiance: np.ndarray  # (H, W, 3) float32 linear HDR (exposure not applied)
    albedo: np.ndarray  # (H, W, 3) float32 linear base colour
    roughness: np.ndarray  # (H, W) float32
    metallic: np.ndarray  # (H, W) float32
    occlusion: np.ndarray  # (H, W) float32
    normal: np.ndarray  # (H, W, 3) float32 unit world normal (after normal mapping)
    depth: np.ndarray  # (H, W) float32 distance along the camera's z axis
    mask: np.ndarray  # (H, W) float32 coverage in [0, 1]
    uv: np.ndarray  # (H, W, 2) float32 texture coordinates
    extras: dict = field(default_factory=dict)


class PBRRenderer:
    def __init__(self, ctx: moderngl.Context, ibl_config: IBLConfig = IBLConfig()):
        make_current(ctx)
        self.ctx = ctx
        self.mesh_program = ctx.program(vertex_shader=shader_source("mesh.vert"), fragment_shader=shader_source("mesh_pbr.frag"))
        self.background_program = ctx.program(vertex_shader=shader_source("fullscreen.vert"), fragment_shader=shader_source("background.frag"))
        self.tonemap_program = ctx.program(vertex_shader=shader_source("fullscreen.vert"), fragment_shader=shader_source("tonemap.frag"))
        self._fullscreen = ctx.vertex_array(self.background_program, [])
        self._fullscreen_tonemap = ctx.vertex_array(self.tonemap_program, [])
        self.channel_program = ctx.program(vertex_shader=shader_source("fullscreen.vert"), fragment_shader=shader_source("channel_view.frag"))
        self._fullscreen_channel = ctx.vertex_array(self.channel_program, [])
        self.resolve_program = ctx.program(vertex_shader=shader_source("fullscreen.vert"), fragment_shader=shader_source("resolve_supersample.frag"))
        self._fullscreen_resolve = ctx.vertex_array(self.resolve_program, [])
        self.baker = IBLBaker(ctx, ibl_config)
        self._targets: dict[tuple[int, int], _GBuffer] = {}

    # ---- resources -------------------------------------------------------------------------
    def upload(self, meshes: list[MeshData], transform: np.ndarray | None = None) -> GpuScene:
        make_current(self.ctx)
        return GpuScene(self.ctx, self.mesh_program, meshes, transform)

    def prepare_lighting(self, environment, rotation_deg: float = 0.0, intensity_ev: float = 0.0) -> Lighting:
        make_current(self.ctx)
        return Lighting(self.baker.bake(environment), rotation_deg, intensity_ev)

    # ---- offscreen ---------------------------------------------------------------------------
    def render(self, scene: GpuScene, cameras, lighting: Lighting, settings: RenderSettings = RenderSettings()) -> list[RenderOutput]:
        return [self.render_view(scene, cam, lighting, settings) for cam in cameras]

    def render_view(self, scene: GpuScene, camera, lighting: Lighting, settings: RenderSettings = RenderSettings()) -> RenderOutput:
        make_current(self.ctx)
        k = int(settings.supersample)
        cam = _scaled_camera(camera, k) if k > 1 else camera
        target = self._target(int(cam.width), int(cam.height))
        self._draw_gbuffer(target, scene, cam, lighting, settings)
        self._tonemap(target.texture("radiance"), target.display_fbo, settings)
        if k == 1:
            return target.read()
        resolved = self._target(int(camera.width), int(camera.height), _ResolvedBuffer)
        self._resolve(target, resolved, k)
        return resolved.read()

    # ---- window ------------------------------------------------------------------------------
    def draw_to_framebuffer(self, framebuffer: moderngl.Framebuffer, scene: GpuScene, camera, lighting: Lighting, settings: RenderSettings = RenderSettings()) -> None:
        """Render and tone-map into an existing framebuffer (e.g. ctx.screen) of the camera's size."""
        target = self._target(int(camera.width), int(camera.height))
        self._draw_gbuffer(target, scene, camera, lighting, settings)
        self._tonemap(target.texture("radiance"), framebuffer, settings)

    def draw_channel_to_framebuffer(self, framebuffer: moderngl.Framebuffer, scene: GpuScene, camera, lighting: Lighting,
                                    channel: str, settings: RenderSettings = RenderSettings(),
                                    empty: tuple[float, float, float] = (0.18, 0.18, 0.18)) -> None:
        """One of DISPLAY_CHANNELS into an existing framebuffer of the camera's size: "beauty" as
        draw_to_framebuffer, or a G-buffer channel shown as an image (albedo in sRGB, scalars as grey)."""
        if channel == "beauty":
            return self.draw_to_framebuffer(framebuffer, scene, camera, lighting, settings)
        if channel not in DISPLAY_CHANNELS:
            raise ValueError(f"unknown channel {channel!r}; choose one of {', '.join(DISPLAY_CHANNELS)}")
        target = self._target(int(camera.width), int(camera.height))
        self._draw_gbuffer(target, scene, camera, lighting, settings)
        framebuffer.use()
        prog = self.channel_program
        for unit, name in enumerate(("albedo", "material", "normal_depth")):
            target.texture(name).use(unit)
            _set(prog, f"u_{name}", unit)
        _set(prog, "u_channel", DISPLAY_CHANNELS.index(channel) - 1)
        _set(prog, "u_empty", tuple(float(x) for x in empty))
        self._fullscreen_channel.render(moderngl.TRIANGLES, vertices=3)

    # ---- passes ------------------------------------------------------------------------------
    def _draw_gbuffer(self, target: "_GBuffer", scene: GpuScene, camera, lighting: Lighting, settings: RenderSettings) -> None:
        ctx = self.ctx
        maps = lighting.maps
        target.fbo.use()
        target.fbo.clear(*settings.clear_color, 0.0, depth=1.0)
        env_rotation = rotation_about_z(-lighting.rotation_deg)  # world -> environment frame
        intensity = 2.0**lighting.intensity_ev
        c2w = np.asarray(camera.c2w, dtype=np.float64)

        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE | moderngl.BLEND)
        bg = self.background_program
        maps.environment_cube.use(0)
        _set(bg, "u_environment_cube", 0)
        _write(bg, "u_environment_rotation", env_rotation)
        _set(bg, "u_environment_intensity", intensity)
        _set(bg, "u_background_lod", float(settings.background_blur))
        _set(bg, "u_show_environment", int(settings.show_environment))
        _set(bg, "u_intrinsics", (float(camera.fx), float(camera.fy), float(camera.cx), float(camera.cy)))
        _set(bg, "u_image_size", (float(camera.width), float(camera.height)))
        _write(bg, "u_camera_rotation", c2w[:3, :3])
        if settings.show_environment:
            self._fullscreen.render(moderngl.TRIANGLES, vertices=3)

        ctx.enable(moderngl.DEPTH_TEST)
        prog = self.mesh_program
        near, far = near_far_for_bounds(camera, scene.bounds)
        _write(prog, "u_view_projection", view_projection_matrix(camera, near, far))
        _write(prog, "u_model", scene.transform)
        _write(prog, "u_normal_matrix", np.linalg.inv(scene.transform[:3, :3]).T)
        _set(prog, "u_camera_position", tuple(c2w[:3, 3]))
        _set(prog, "u_camera_forward", tuple(c2w[:3, 2]))
        maps.specular_cube.use(5)
        maps.irradiance_cube.use(6)
        self.baker.brdf_lut.use(7)
        _set(prog, "u_specular_cube", 5)
        _set(prog, "u_irradiance_cube", 6)
        _set(prog, "u_brdf_lut", 7)
        _set(prog, "u_specular_max_lod", float(maps.specular_levels - 1))
        _write(prog, "u_environment_rotation", env_rotation)
        _set(prog, "u_environment_intensity", intensity)
        _set(prog, "u_multiple_scattering", int(settings.multiple_scattering))
        mirrored = np.linalg.det(scene.transform[:3, :3]) < 0
        ctx.front_face = "cw" if mirrored else "ccw"
        for mesh in scene.meshes:
            m = mesh.material
            if m.double_sided:
                ctx.disable(moderngl.CULL_FACE)
            else:
                ctx.enable(moderngl.CULL_FACE)
            for unit, slot in enumerate(("base_color_texture", "metallic_roughness_texture", "normal_texture", "occlusion_texture", "emissive_texture")):
                mesh.textures[slot].use(unit)
                _set(prog, f"u_{slot}", unit)
            _set(prog, "u_base_color_factor", tuple(float(x) for x in m.base_color_factor))
            _set(prog, "u_metallic_factor", float(m.metallic_factor))
            _set(prog, "u_roughness_factor", float(m.roughness_factor))
            _set(prog, "u_emissive_factor", tuple(float(x) for x in m.emissive_factor))
            _set(prog, "u_normal_scale", float(m.normal_scale))
            _set(prog, "u_occlusion_strength", float(m.occlusion_strength))
            _set(prog, "u_has_normal_texture", int(m.normal_texture is not None))
            _set(prog, "u_alpha_mask", int(m.alpha_mode == "MASK"))
            _set(prog, "u_alpha_cutoff", float(m.alpha_cutoff))
            mesh.vao.render(moderngl.TRIANGLES)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.CULL_FACE)
        ctx.front_face = "ccw"

    def _tonemap(self, radiance: moderngl.Texture, framebuffer: moderngl.Framebuffer, settings: RenderSettings) -> None:
        framebuffer.use()
        radiance.use(0)
        prog = self.tonemap_program
        _set(prog, "u_radiance", 0)
        _set(prog, "u_exposure", 2.0**settings.exposure_ev)
        _set(prog, "u_tonemapper", TONEMAPPERS.index(settings.tonemapper))
        self._fullscreen_tonemap.render(moderngl.TRIANGLES, vertices=3)

    def _resolve(self, source: "_GBuffer", target: "_ResolvedBuffer", factor: int) -> None:
        target.fbo.use()
        prog = self.resolve_program
        for unit, name in enumerate(GBUFFER_ATTACHMENTS):
            source.texture(name).use(unit)
            _set(prog, f"u_{name}", unit)
        source.display.use(len(GBUFFER_ATTACHMENTS))
        _set(prog, "u_display", len(GBUFFER_ATTACHMENTS))
        _set(prog, "u_factor", factor)
        self._fullscreen_resolve.render(moderngl.TRIANGLES, vertices=3)

    def _target(self, width: int, height: int, kind: type | None = None):
        kind = kind or _GBuffer
        key = (width, height, kind)
        if key not in self._targets:
            if len(self._targets) >= 6:  # sizes change rarely; keep a few, drop the oldest
                oldest = next(iter(self._targets))
                self._targets.pop(oldest).release()
            self._targets[key] = kind(self.ctx, width, height)
        return self._targets[key]

    def release(self) -> None:
        for target in self._targets.values():
            target.release()
        self._targets = {}
        self.baker.release()
        for obj in (self._fullscreen, self._fullscreen_tonemap, self._fullscreen_channel, self._fullscreen_resolve,
                    self.mesh_program, self.background_program, self.tonemap_program, self.channel_program,
                    self.resolve_program):
            obj.release()


class _GBuffer:
    def __init__(self, ctx: moderngl.Context, width: int, height: int):
        self.size = (width, height)
        self.textures = [ctx.texture((width, height), 4, dtype="f4") for _ in GBUFFER_ATTACHMENTS]
        for tex in self.textures:
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth = ctx.depth_renderbuffer((width, height))
        self.fbo = ctx.framebuffer(color_attachments=self.textures, depth_attachment=self.depth)
        self.display = ctx.texture((width, height), 4, dtype="f1")
        self.display_fbo = ctx.framebuffer(color_attachments=[self.display])

    def texture(self, name: str) -> moderngl.Texture:
        return self.textures[GBUFFER_ATTACHMENTS.index(name)]

    def read(self) -> RenderOutput:
        w, h = self.size
        display = np.frombuffer(self.display_fbo.read(components=4, dtype="f1"), dtype=np.uint8).reshape(h, w, 4)[::-1]
        return _read_gbuffer(self.fbo, self.size, display[:, :, :3].astype(np.float32) / 255.0)

    def release(self) -> None:
        for obj in (self.fbo, self.display_fbo, self.depth, self.display, *self.textures):
            obj.release()


class _ResolvedBuffer:
    """The output-size G-buffer that resolve_supersample.frag writes: the five G-buffer attachments
    (albedo's alpha = coverage) and the averaged display image, all float."""

    def __init__(self, ctx: moderngl.Context, width: int, height: int):
        self.size = (width, height)
        self.textures = [ctx.texture((width, height), 4, dtype="f4") for _ in range(len(GBUFFER_ATTACHMENTS) + 1)]
        self.fbo = ctx.framebuffer(color_attachments=self.textures)

    def read(self) -> RenderOutput:
        w, h = self.size
        beauty = _read_attachment(self.fbo, len(GBUFFER_ATTACHMENTS), w, h)
        return _read_gbuffer(self.fbo, self.size, beauty[:, :, :3].copy())

    def release(self) -> None:
        for obj in (self.fbo, *self.textures):
            obj.release()


def _read_attachment(fbo: moderngl.Framebuffer, index: int, w: int, h: int) -> np.ndarray:
    data = np.frombuffer(fbo.read(components=4, attachment=index, dtype="f4"), dtype=np.float32)
    return data.reshape(h, w, 4)[::-1]  # GL rows start at the bottom


def _read_gbuffer(fbo: moderngl.Framebuffer, size: tuple[int, int], beauty: np.ndarray) -> RenderOutput:
    """The G-buffer attachments (GBUFFER_ATTACHMENTS' order, albedo's alpha = coverage) of `fbo` as a
    RenderOutput with the given display image."""
    w, h = size
    radiance, albedo, material, normal_depth, uv = (_read_attachment(fbo, i, w, h) for i in range(len(GBUFFER_ATTACHMENTS)))
    return RenderOutput(
        beauty=beauty,
        radiance=radiance[:, :, :3].copy(),
        albedo=albedo[:, :, :3].copy(),
        roughness=material[:, :, 0].copy(),
        metallic=material[:, :, 1].copy(),
        occlusion=material[:, :, 2].copy(),
        normal=normal_depth[:, :, :3].copy(),
        depth=normal_depth[:, :, 3].copy(),
        mask=albedo[:, :, 3].copy(),
        uv=uv[:, :, :2].copy(),
    )


def _scaled_camera(camera, k: int):
    return SimpleNamespace(
        width=int(camera.width) * k, height=int(camera.height) * k,
        fx=camera.fx * k, fy=camera.fy * k, cx=camera.cx * k, cy=camera.cy * k, c2w=camera.c2w,
    )


def box_downsample(image: np.ndarray, k: int) -> np.ndarray:
    """(kH, kW, ...) -> (H, W, ...): the mean of each k x k block, as the supersampling resolves radiance
    (background counted as black)."""
    if k == 1:
        return image
    h, w = image.shape[0] // k, image.shape[1] // k
    return image.reshape(h, k, w, k, *image.shape[2:]).mean(axis=(1, 3))


def downsample_reference(out: RenderOutput, k: int) -> RenderOutput:
    """Box-filter k x k blocks; G-buffer channels average over covered sub-pixels only. The numpy
    reference of resolve_supersample.frag, which render_view uses (tests hold the two together)."""

    def blocks(a: np.ndarray) -> np.ndarray:
        h, w = a.shape[0] // k, a.shape[1] // k
        return a.reshape(h, k, w, k, *a.shape[2:])

    cov = blocks(out.mask)
    weight = cov.sum(axis=(1, 3))
    safe = np.maximum(weight, 1e-12)

    def covered_mean(a: np.ndarray) -> np.ndarray:
        b = blocks(a)
        c = cov.reshape(cov.shape + (1,) * (b.ndim - cov.ndim))
        mean = (b * c).sum(axis=(1, 3)) / safe.reshape(safe.shape + (1,) * (b.ndim - 4))
        return np.where(weight.reshape(weight.shape + (1,) * (b.ndim - 4)) > 0, mean, 0.0).astype(np.float32)

    normal = covered_mean(out.normal)
    length = np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.where(length > 1e-8, normal / np.maximum(length, 1e-8), 0.0).astype(np.float32)
    return replace(
        out,
        beauty=box_downsample(out.beauty, k).astype(np.float32),
        radiance=box_downsample(out.radiance, k).astype(np.float32),
        albedo=covered_mean(out.albedo),
        roughness=covered_mean(out.roughness),
        metallic=covered_mean(out.metallic),
        occlusion=covered_mean(out.occlusion),
        normal=normal,
        depth=covered_mean(out.depth),
        mask=(weight / (k * k)).astype(np.float32),
        uv=covered_mean(out.uv),
    )


def _set(program: moderngl.Program, name: str, value) -> None:
    if name in program:  # the GLSL compiler removes uniforms a program does not use
        program[name].value = value


def _write(program: moderngl.Program, name: str, matrix: np.ndarray) -> None:
    if name in program:
        program[name].write(gl_bytes(matrix))
