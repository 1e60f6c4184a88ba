"""The renderer draws into a real window's OpenGL context (glfw under Xvfb), as the app will."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.cameras import Camera, look_at
from lirm.renderer.context import context_from_current_window, describe
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.primitives import uv_sphere

pytestmark = pytest.mark.display


@pytest.fixture
def window(x_display):
    glfw = pytest.importorskip("glfw")
    if not glfw.init():
        pytest.skip(f"glfw could not initialise on display {x_display}")
    glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
    glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
    glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
    glfw.window_hint(glfw.RESIZABLE, False)
    handle = glfw.create_window(160, 120, "lirm renderer test", None, None)
    if not handle:
        glfw.terminate()
        pytest.skip("glfw could not create an OpenGL 4.3 core window")
    glfw.make_context_current(handle)
    yield glfw, handle
    glfw.destroy_window(handle)
    glfw.terminate()


def test_render_into_a_window_matches_the_offscreen_render(window):
    glfw, handle = window
    ctx = context_from_current_window()
    assert "OpenGL 4" in describe(ctx)
    renderer = PBRRenderer(ctx)
    env = Environment(np.ones((64, 128, 3), np.float32))
    dirs, _ = env.texel_directions()
    env.radiance = (1.0 + dirs).astype(np.float32)
    lighting = renderer.prepare_lighting(env)
    camera = Camera.from_fov(160, 120, 45.0, look_at((0.5, -3.0, 1.0), (0, 0, 0)))
    scene = renderer.upload([uv_sphere(material=PBRMaterial(base_color_factor=(0.8, 0.3, 0.2, 1), metallic_factor=0.0, roughness_factor=0.4))])
    try:
        offscreen = renderer.render_view(scene, camera, lighting, RenderSettings())
        renderer.draw_to_framebuffer(ctx.screen, scene, camera, lighting, RenderSettings())
        shown = np.frombuffer(ctx.screen.read(components=3), np.uint8).reshape(120, 160, 3)[::-1]
        glfw.swap_buffers(handle)
        np.testing.assert_allclose(shown / 255.0, offscreen.beauty, atol=1.5 / 255)
        assert 0.1 < offscreen.mask.mean() < 0.9  # the sphere is in view, with background around it
    finally:
        scene.release()
        lighting.maps.release()
        renderer.release()
