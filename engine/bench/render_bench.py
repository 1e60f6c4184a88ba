"""`lirm bench render`: renderer speed on this machine.

Measures (1) environment preprocessing of an HDR (file read, cube conversion, GGX prefiltering,
irradiance; the BRDF table once per context), and (2) frames per second of a model with the full
G-buffer at several sizes: GPU time alone (draw + finish) and the whole offscreen path with every
channel read back to numpy, which is what training-data generation and baking pay.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

from lirm.renderer.context import create_headless_context, describe
from lirm.renderer.ibl import IBL_PRESETS, IBLBaker
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings

from ..assets.asset_source import resolve_asset
from ..assets.environment_files import resolve_environment
from ..orbit_render import OrbitRenderConfig, normalizing_transform, orbit_for


@dataclass
class RenderBenchConfig:
    model: str = "vase"
    environment: str = "studio"
    sizes: tuple[int, ...] = (512, 1024)
    frames: int = 20
    environment_repeats: int = 3
    ibl_preset: str = "default"


@dataclass
class RenderBenchResult:
    device: str
    model: str
    environment: str
    environment_size: tuple[int, int]
    ibl_preset: str = "default"
    environment_seconds: dict[str, float] = field(default_factory=dict)
    fps: dict[str, dict[str, float]] = field(default_factory=dict)  # size -> {"gpu": fps, "readback": fps}

    def table(self) -> str:
        lines = [f"device: {self.device}", f"model: {self.model}",
                 f"environment: {self.environment} ({self.environment_size[0]}x{self.environment_size[1]})",
                 "", f"environment preprocessing, IBL preset '{self.ibl_preset}' (median seconds)"]
        lines += [f"  {k:<20} {v:8.3f}" for k, v in self.environment_seconds.items()]
        lines += ["", f"  {'size':<12} {'GPU only fps':>14} {'+ G-buffer readback fps':>24}"]
        lines += [f"  {size:<12} {v['gpu']:>14.1f} {v['readback']:>24.1f}" for size, v in self.fps.items()]
        return "\n".join(lines)


def run_render_bench(config: RenderBenchConfig, progress=None) -> RenderBenchResult:
    say = progress or (lambda message: None)
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx, IBL_PRESETS[config.ibl_preset])
    try:
        say(f"loading {config.environment}")
        t0 = time.perf_counter()
        environment = resolve_environment(config.environment)
        load_seconds = time.perf_counter() - t0
        result = RenderBenchResult(describe(ctx), str(config.model), environment.name, (environment.width, environment.height),
                                   ibl_preset=config.ibl_preset)

        t0 = time.perf_counter()
        lut_baker = IBLBaker(ctx)
        _ = lut_baker.brdf_lut
        ctx.finish()
        lut_seconds = time.perf_counter() - t0
        lut_baker.release()

        say("timing environment preprocessing")
        stages: dict[str, list[float]] = {}
        lighting = None
        for _ in range(config.environment_repeats):
            t0 = time.perf_counter()
            if lighting is not None:
                lighting.maps.release()
            lighting = renderer.prepare_lighting(environment)
            stages.setdefault("total (GPU)", []).append(time.perf_counter() - t0)
            for k, v in lighting.maps.timings.items():
                stages.setdefault(k, []).append(v)
        result.environment_seconds = {"file read": load_seconds, **{k: statistics.median(v) for k, v in stages.items()}, "BRDF LUT (once)": lut_seconds}

        say(f"loading {config.model}")
        model = resolve_asset(config.model)
        scene = renderer.upload(model.meshes, normalizing_transform(model.bounds))
        try:
            for size in config.sizes:
                say(f"rendering {config.frames} frames at {size}x{size}")
                cameras = orbit_for(OrbitRenderConfig(views=config.frames, width=size, height=size))
                settings = RenderSettings(supersample=1)
                renderer.render_view(scene, cameras[0], lighting, settings)  # warm-up: shaders, targets
                screen = ctx.simple_framebuffer((size, size))  # stands in for a window
                t0 = time.perf_counter()
                for cam in cameras:
                    renderer.draw_to_framebuffer(screen, scene, cam, lighting, settings)
                ctx.finish()
                gpu = len(cameras) / (time.perf_counter() - t0)
                screen.release()
                t0 = time.perf_counter()
                for cam in cameras:
                    renderer.render_view(scene, cam, lighting, settings)
                readback = len(cameras) / (time.perf_counter() - t0)
                result.fps[f"{size}x{size}"] = {"gpu": gpu, "readback": readback}
        finally:
            scene.release()
            lighting.maps.release()
        return result
    finally:
        renderer.release()
        ctx.release()
