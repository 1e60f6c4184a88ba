"""Guidance: where to shoot next, how much of the object is covered, the view-sphere heat map."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from .common import job_progress


class GuidancePanel:
    title = "Guidance"

    def __init__(self, app):
        self.app = app

    def draw(self) -> None:
        app, state, actions = self.app, self.app.state, self.app.actions
        if state.capture_dir is None:
            imgui.text("Open a capture to get guidance.")
            return
        if imgui.button("Suggest next views"):
            actions.ask_guidance()
        app.note_widget("suggest")
        for job in app.jobs.running("suggest"):
            job_progress(job, app.jobs.cancel)
        changed, show = imgui.checkbox("show coverage on the mesh", state.choices.view.show_coverage)
        if changed:
            actions.set_show_coverage(show)
        g = state.guidance
        if not g:
            imgui.text_wrapped("No suggestions yet.")
            return
        imgui.text_wrapped(f"surface: {g['surface']}")
        imgui.text_wrapped(f"covered now {100 * g['coverage_now']:.0f}%, after these shots {100 * g['coverage_after']:.0f}%")
        for note in g.get("notes", []):
            imgui.text_wrapped(f"note: {note}")
        for s in g["suggestions"]:
            # Wrapped, not bullet_text: the panel is narrow and the sentence is what the photographer needs.
            new = s.get("new_coverage", s["gain"])  # suggestions.json before new_coverage had only the gain
            worth = f"+{100 * new:.0f}% of the surface" if new >= 0.005 else "a squarer look"
            imgui.text_wrapped(f"{s['rank']}. {s['sentence']} (azimuth {s['azimuth_deg']:.0f}°, elevation "
                               f"{s['elevation_deg']:.0f}°; {worth})")
        if "heat_map" in g:
            self._view_sphere(g)

    def _view_sphere(self, g: dict) -> None:
        """Azimuth across, elevation up: the gain of each candidate view (brighter = more to gain), the
        cameras shot so far (blue dots) and the suggested shots (numbered, green)."""
        from lirm.engine.guidance.next_views import camera_angles

        heat = np.asarray(g["heat_map"]["gain"], np.float64)
        elevations = g["heat_map"]["elevations_deg"]
        step = float(g["heat_map"]["azimuth_step_deg"])
        rows, cols = heat.shape
        width = imgui.get_content_region_avail().x
        cell = width / cols
        height = cell * rows * 1.6
        origin = imgui.get_cursor_screen_pos()
        draw = imgui.get_window_draw_list()
        top = max(float(heat.max()), 1e-9)
        row_h = height / rows
        for r in range(rows):
            for c in range(cols):
                v = heat[r, c] / top
                colour = imgui.IM_COL32(int(40 + 215 * v), int(30 + 150 * v * v), int(60 * (1 - v)), 255)
                y = origin.y + (rows - 1 - r) * row_h
                draw.add_rect_filled(imgui.ImVec2(origin.x + c * cell, y), imgui.ImVec2(origin.x + (c + 1) * cell, y + row_h), colour)

        def at(azimuth: float, elevation: float) -> imgui.ImVec2:
            """Cell centres are the candidates: column c is azimuth c * step, row r is elevations[r]."""
            column = ((azimuth + step / 2) % 360.0) / step - 0.5
            row = float(np.interp(elevation, elevations, np.arange(rows)))
            return imgui.ImVec2(origin.x + (column + 0.5) * cell, origin.y + (rows - 1 - row + 0.5) * row_h)

        for camera in self.app.capture_cameras:
            azimuth, elevation, _ = camera_angles(camera)
            draw.add_circle_filled(at(azimuth, elevation), 3.0, imgui.IM_COL32(120, 200, 255, 255))
        for s in g["suggestions"]:
            p = at(s["azimuth_deg"], s["elevation_deg"])
            draw.add_circle(p, 7.0, imgui.IM_COL32(120, 255, 120, 255), 0, 2.0)
            draw.add_text(imgui.ImVec2(p.x - 3, p.y - 7), imgui.IM_COL32(120, 255, 120, 255), str(s["rank"]))
        imgui.dummy(imgui.ImVec2(width, height))
        imgui.text("azimuth 0-360° across, elevation -10..80° up; blue: shot, green: suggested")
