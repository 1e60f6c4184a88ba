"""lirm.app: the interactive window (glfw + imgui-bundle + moderngl).

Not built yet: the desktop app is issue 9. Nothing here is importable API so far."""
