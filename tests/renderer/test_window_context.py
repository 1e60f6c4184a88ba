"""The renderer draws into a real window's OpenGL context (glfw under Xvfb), as the app will.

The check runs in its own process, like the app: a thread that has the test session's EGL context
current cannot make a GLX window context current (X error BadAccess on X_GLXMakeCurrent).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.display

WINDOW_CHECK = r"""
import json, sys
import glfw, numpy as np
from lirm.engine.cameras import Camera, look_at
from lirm.renderer.context import context_from_current_window, describe
from lirm.renderer.environment import Environment
from lirm.renderer.material import PBRMaterial
from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings
from lirm.renderer.primitives import uv_sphere

if not glfw.init():
    print(json.dumps({"skip": "glfw could not initialise"})); sys.exit(0)
glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 4)
glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
glfw.window_hint(glfw.RESIZABLE, False)
window = glfw.create_window(160, 120, "lirm renderer test", None, None)
if not window:
    print(json.dumps({"skip": "no OpenGL 4.3 core window"})); sys.exit(0)
glfw.make_context_current(window)
ctx = context_from_current_window()
renderer = PBRRenderer(ctx)
env = Environment(np.ones((64, 128, 3), np.float32))
dirs, _ = env.texel_directions()
env.radiance = (1.0 + dirs).astype(np.float32)
lighting = renderer.prepare_lighting(env)
camera = Camera.from_fov(160, 120, 45.0, look_at((0.5, -3.0, 1.0), (0, 0, 0)))
material = PBRMaterial(base_color_factor=(0.8, 0.3, 0.2, 1), metallic_factor=0.0, roughness_factor=0.4)
scene = renderer.upload([uv_sphere(material=material)])
offscreen = renderer.render_view(scene, camera, lighting, RenderSettings())
renderer.draw_to_framebuffer(ctx.screen, scene, camera, lighting, RenderSettings())
shown = np.frombuffer(ctx.screen.read(components=3), np.uint8).reshape(120, 160, 3)[::-1] / 255.0
glfw.swap_buffers(window)
print(json.dumps({
    "device": describe(ctx),
    "max_difference": float(np.abs(shown - offscreen.beauty).max()),
    "coverage": float(offscreen.mask.mean()),
    "window_std": float(shown.std()),
}))
glfw.terminate()
"""


def test_render_into_a_window_matches_the_offscreen_render(x_display):
    env = {**os.environ, "DISPLAY": x_display}
    proc = subprocess.run([sys.executable, "-c", WINDOW_CHECK], capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 0, proc.stderr
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    if "skip" in result:
        pytest.skip(result["skip"])
    assert "OpenGL 4" in result["device"]
    assert result["max_difference"] <= 1.5 / 255  # the window shows exactly the offscreen beauty
    assert 0.1 < result["coverage"] < 0.9  # the sphere is in view with background around it
    assert result["window_std"] > 0.05  # not a blank window
