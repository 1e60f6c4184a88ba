"""OpenGL contexts: a headless EGL one for offscreen work, or the current context of a window.

The renderer needs OpenGL 4.3 (compute shaders for environment preprocessing). Mesa's llvmpipe
gives 4.5 through EGL on machines without a GPU; an NVIDIA driver gives the same through its
EGL vendor library.

One thread, one kind of context: while a headless EGL context is current on a thread, making a GLX
window context current on that thread fails (X error BadAccess on X_GLXMakeCurrent, seen with Mesa
22 under Xvfb). Leave the EGL context first (`ctx.__exit__(None, None, None)`, or create it inside
`with ctx:`), or keep headless work in another process.
"""

from __future__ import annotations

import moderngl

REQUIRED_GL_VERSION = 430


class GLContextError(RuntimeError):
    """No usable OpenGL context; the message says what to install or set."""


def create_headless_context(require: int = REQUIRED_GL_VERSION) -> moderngl.Context:
    """A standalone EGL context with no window (tests, command line, synthetic data)."""
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=require)
    except Exception as exc:  # moderngl raises plain Exception subclasses from the loader
        raise GLContextError(
            "could not create a headless OpenGL context through EGL "
            f"({exc}). On Debian install the loaders with "
            "`apt-get install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri` (`make setup` does this); "
            "on an NVIDIA machine set __EGL_VENDOR_LIBRARY_FILENAMES to the driver's 10_nvidia.json."
        ) from exc
    ctx.extra = {"headless": True}
    return ctx


def make_current(ctx: moderngl.Context) -> None:
    """Make a headless context current in this thread again. Creating (or releasing) another EGL
    context makes that one current, after which this context's draws would silently go nowhere;
    a window's context is left to its toolkit, which owns its currency."""
    if isinstance(ctx.extra, dict) and ctx.extra.get("headless"):
        ctx.__enter__()


def context_from_current_window(require: int = REQUIRED_GL_VERSION) -> moderngl.Context:
    """Wrap the OpenGL context that a window toolkit (glfw, imgui-bundle) has made current."""
    try:
        return moderngl.create_context(require=require)
    except Exception as exc:
        raise GLContextError(
            f"the window's OpenGL context cannot be used ({exc}); the renderer needs OpenGL "
            f"{require // 100}.{require % 100 // 10} core: ask the window toolkit for that version"
        ) from exc


def describe(ctx: moderngl.Context) -> str:
    info = ctx.info
    return f"{info.get('GL_RENDERER', '?')} (OpenGL {ctx.version_code // 100}.{ctx.version_code % 100 // 10})"
