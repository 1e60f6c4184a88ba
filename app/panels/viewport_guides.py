"""What a 3D viewport user expects over the image (Blender, Object Capture, nerfstudio): a ground grid
on y = 0 of the export (z = 0 of the viewport's +Z-up world), an axis gizmo, a scale bar in real units
when the capture has a real size (else it says the scale is arbitrary), and a help overlay of the
mouse and keyboard controls (F1). All drawn with imgui's draw list from the orbit camera: nothing is
re-rendered for them."""

from __future__ import annotations

import math

import numpy as np
from imgui_bundle import imgui

GRID_COLOUR = imgui.IM_COL32(200, 200, 200, 60)
AXIS_COLOURS = {"X": imgui.IM_COL32(235, 80, 80, 255), "Y": imgui.IM_COL32(110, 210, 90, 255), "Z": imgui.IM_COL32(90, 140, 250, 255)}
HELP = (("left drag", "orbit"), ("right drag / shift + drag", "pan"), ("wheel", "zoom"), ("F or double click", "frame the asset"),
        ("Ctrl+N", "new project from photos"), ("Ctrl+O", "open a capture"), ("F1", "this help"))


def nice_length(target: float) -> float:
    """The 1, 2 or 5 x 10^k closest below `target` (> 0)."""
    power = 10.0 ** math.floor(math.log10(target))
    for step in (5.0, 2.0, 1.0):
        if step * power <= target:
            return step * power
    return power


def format_length(value: float, metres: bool) -> str:
    if not metres:
        return f"{value:g} unit" if value == 1 else f"{value:g} units"
    if value >= 1.0:
        return f"{value:g} m"
    if value >= 0.01:
        return f"{value * 100:g} cm"
    return f"{value * 1000:g} mm"


def draw_grid(draw, origin, camera, bounds: np.ndarray, width: int, height: int) -> float:
    """Lines on the ground (z = 0) about 10 to a side around the asset; returns their spacing."""
    size = float(np.max(bounds[1] - bounds[0])) or 1.0
    spacing = nice_length(size / 2.0)
    centre = np.round(bounds.mean(axis=0)[:2] / spacing) * spacing
    half = 5
    ticks = np.arange(-half, half + 1) * spacing
    for along in (0, 1):
        for t in ticks:
            a = np.zeros(3)
            b = np.zeros(3)
            a[along], b[along] = centre[along] - half * spacing, centre[along] + half * spacing
            a[1 - along] = b[1 - along] = centre[1 - along] + t
            _segment(draw, origin, camera, a, b, width, height, GRID_COLOUR)
    return spacing


def _segment(draw, origin, camera, a, b, width, height, colour, pieces: int = 16) -> None:
    """A world segment cut into pieces, each drawn when both its ends are in front of the camera."""
    points = a[None] + np.linspace(0.0, 1.0, pieces + 1)[:, None] * (b - a)[None]
    xy, z = camera.project(points)
    front = z > 1e-6
    for k in range(pieces):
        if front[k] and front[k + 1]:
            draw.add_line(imgui.ImVec2(origin.x + xy[k, 0], origin.y + xy[k, 1]),
                          imgui.ImVec2(origin.x + xy[k + 1, 0], origin.y + xy[k + 1, 1]), colour, 1.0)


def draw_axis_gizmo(draw, origin, camera, height: int, length: float = 28.0) -> None:
    """The exported asset's axes (glTF: +Y up) in the bottom-left corner, as its user will meet them.
    The viewport's world is +Z up: glTF's X, Y, Z are its x, z and -y."""
    centre = np.array([origin.x + 40.0, origin.y + height - 40.0])
    rotation = np.asarray(camera.c2w)[:3, :3].T  # world -> camera
    gltf_axes = {"X": np.array([1.0, 0.0, 0.0]), "Y": np.array([0.0, 0.0, 1.0]), "Z": np.array([0.0, -1.0, 0.0])}
    order = sorted(gltf_axes, key=lambda name: -(rotation @ gltf_axes[name])[2])  # far ones first
    draw.add_circle_filled(imgui.ImVec2(*centre), length + 8, imgui.IM_COL32(0, 0, 0, 90))
    for name in order:
        d = rotation @ gltf_axes[name]
        tip = centre + length * np.array([d[0], d[1]])  # camera x right, y down: the image's own axes
        draw.add_line(imgui.ImVec2(*centre), imgui.ImVec2(*tip), AXIS_COLOURS[name], 2.0)
        draw.add_text(imgui.ImVec2(tip[0] - 4, tip[1] - 7), AXIS_COLOURS[name], name)


def draw_scale_bar(draw, origin, camera, target: np.ndarray, width: int, height: int, metres: bool) -> str:
    """A bar of a round length at the orbit target's depth, bottom right; returns its label."""
    depth = float((np.asarray(target) - np.asarray(camera.c2w)[:3, 3]) @ np.asarray(camera.c2w)[:3, 2])
    if depth <= 1e-6:
        return ""
    pixels_per_unit = camera.fy / depth
    length = nice_length(120.0 / pixels_per_unit)
    bar = length * pixels_per_unit
    label = format_length(length, metres) + ("" if metres else " (arbitrary scale: set the real size in Export)")
    text = imgui.calc_text_size(label)
    x1, y = origin.x + width - 14.0, origin.y + height - 18.0
    x0 = x1 - bar
    draw.add_rect_filled(imgui.ImVec2(min(x0, x1 - text.x) - 6, y - text.y - 10), imgui.ImVec2(x1 + 6, y + 6), imgui.IM_COL32(0, 0, 0, 120), 4.0)
    white = imgui.IM_COL32(240, 240, 240, 255)
    draw.add_line(imgui.ImVec2(x0, y), imgui.ImVec2(x1, y), white, 2.0)
    for x in (x0, x1):
        draw.add_line(imgui.ImVec2(x, y - 5), imgui.ImVec2(x, y + 3), white, 2.0)
    draw.add_text(imgui.ImVec2(x1 - text.x, y - text.y - 6), white, label)
    return label


def draw_help(draw, origin, width: int) -> None:
    lines = [f"{keys}: {what}" for keys, what in HELP]
    font_height = imgui.get_font_size()
    w = max(imgui.calc_text_size(line).x for line in lines) + 24
    h = (font_height + 4) * (len(lines) + 1) + 16
    x0, y0 = origin.x + width - w - 12, origin.y + 12
    draw.add_rect_filled(imgui.ImVec2(x0, y0), imgui.ImVec2(x0 + w, y0 + h), imgui.IM_COL32(0, 0, 0, 200), 6.0)
    draw.add_text(imgui.ImVec2(x0 + 12, y0 + 8), imgui.IM_COL32(255, 255, 255, 255), "Viewport controls (F1 closes)")
    for k, line in enumerate(lines, start=1):
        draw.add_text(imgui.ImVec2(x0 + 12, y0 + 8 + k * (font_height + 4)), imgui.IM_COL32(220, 220, 220, 255), line)
