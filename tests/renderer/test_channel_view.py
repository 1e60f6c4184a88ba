"""The viewport's channel views match the renderer's own G-buffer read-back (the reference path)."""

from __future__ import annotations

import numpy as np

from lirm.engine.cameras import orbit_camera
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import DISPLAY_CHANNELS, RenderSettings
from lirm.renderer.primitives import uv_sphere
from lirm.renderer.tonemap import linear_to_srgb


def test_channels_shown_equal_the_gbuffer(gl_context, renderer):
    material = PBRMaterial(base_color_factor=(0.7, 0.2, 0.1, 1.0), metallic_factor=0.8, roughness_factor=0.35)
    scene = renderer.upload([uv_sphere(0.7, material=material)])
    lighting = renderer.prepare_lighting(Environment(np.ones((16, 32, 3), np.float32)))
    camera = orbit_camera(30, 20, 2.5, 64, 48, 45.0)
    colour = gl_context.texture((64, 48), 4)
    fbo = gl_context.framebuffer(color_attachments=[colour])
    try:
        reference = renderer.render_view(scene, camera, lighting, RenderSettings(supersample=1))
        inside = reference.mask > 0.999
        expected = {"albedo": linear_to_srgb(reference.albedo), "roughness": reference.roughness[..., None].repeat(3, -1),
                    "metallic": reference.metallic[..., None].repeat(3, -1), "normal": 0.5 * reference.normal + 0.5}
        for channel in DISPLAY_CHANNELS[1:]:
            renderer.draw_channel_to_framebuffer(fbo, scene, camera, lighting, channel)
            shown = np.frombuffer(fbo.read(components=3), np.uint8).reshape(48, 64, 3)[::-1] / 255.0
            assert np.abs(shown[inside] - expected[channel][inside]).max() < 2.5 / 255, channel
            assert np.abs(shown[reference.mask == 0] - 0.18).max() < 2 / 255  # empty pixels: neutral grey
        renderer.draw_channel_to_framebuffer(fbo, scene, camera, lighting, "beauty")
        shown = np.frombuffer(fbo.read(components=3), np.uint8).reshape(48, 64, 3)[::-1] / 255.0
        assert np.abs(shown - reference.beauty).max() < 2 / 255
    finally:
        fbo.release()
        colour.release()
        scene.release()
        lighting.maps.release()
