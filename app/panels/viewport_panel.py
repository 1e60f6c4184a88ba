"""Viewport: the asset under the current HDRI, channel switch, orbit/pan/zoom, cameras as frusta."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui

from lirm.app.viewport import frustum_lines
from lirm.renderer.pbr_renderer import DISPLAY_CHANNELS

from .common import COLOURS
from .viewport_guides import draw_axis_gizmo, draw_grid, draw_help, draw_scale_bar

BACKDROP = 0.18  # the viewport's empty grey (viewport.py clears to it)
INPUT_COLOUR = imgui.IM_COL32(120, 200, 255, 200)
SUGGESTED_COLOUR = imgui.IM_COL32(120, 255, 120, 230)


class ViewportPanel:
    title = "Viewport"

    def __init__(self, app):
        self.app = app
        self._field_size = None
        self._field_shown = None
        self.show_help = False
        self.scale_label = ""  # what the scale bar said last (tests read it)

    def draw(self) -> None:
        app, state = self.app, self.app.state
        viewport = app.viewport
        if viewport is None:
            imgui.text("starting the renderer...")
            return
        view = state.choices.view
        for channel in DISPLAY_CHANNELS + ("field",):
            if imgui.radio_button(channel, view.channel == channel):
                app.actions.set_channel(channel)
            imgui.same_line()
        changed, show = imgui.checkbox("cameras", view.show_cameras)
        if changed:
            app.actions.set_show_cameras(show)
        imgui.same_line()
        changed, guides = imgui.checkbox("guides", view.show_guides)
        if changed:
            app.actions.set_show_guides(guides)
        imgui.same_line()
        if imgui.small_button("?") or imgui.is_key_pressed(imgui.Key.f1, False):
            self.show_help = not self.show_help
        if viewport.frame_times:  # (none yet when a reopened capture starts on the field channel)
            imgui.same_line()
            imgui.text(f"{1000 * viewport.last_render_seconds:.0f} ms")
        size = imgui.get_content_region_avail()
        width, height = int(max(size.x, 16)), int(max(size.y, 16))
        notes: list[tuple[str, str]] = []  # (text, level) written over the image's top-left corner
        if view.channel == "field":
            notes += self._field(width, height)
        else:
            viewport.render(width, height, view.channel, view.rotation_deg, view.exposure_ev, view.background)
        if viewport.texture is None:  # nothing drawn yet (a reopened field channel's first picture is on its way)
            viewport.show_image(np.full((8, 8, 3), BACKDROP, np.float32), width, height)
        origin = imgui.get_cursor_screen_pos()
        imgui.image(imgui.ImTextureRef(viewport.texture.glo), imgui.ImVec2(width, height), imgui.ImVec2(0, 1), imgui.ImVec2(1, 0))
        app.note_widget("viewport")
        self._mouse(width, height)
        if view.show_cameras and app.world_from_capture is not None:
            self._frusta(origin, width, height)
        if view.show_guides and view.channel != "field":
            self._guides(origin, width, height)
        if self.show_help:
            draw_help(imgui.get_window_draw_list(), origin, width)
        if state.capture_dir is not None and state.preview_asset is None and not state.updates:
            notes.append(("No reconstruction yet: pick views in Capture and run an update.", "info"))
        self._overlay(origin, width, notes)

    def _overlay(self, origin, width: int, notes: list[tuple[str, str]]) -> None:
        """Status lines over the image (on a dark band each, wrapped to the image): the image keeps its place."""
        draw = imgui.get_window_draw_list()
        font, font_size = imgui.get_font(), imgui.get_font_size()
        wrap = max(width - 24.0, 40.0)
        y = origin.y + 8
        for text, level in notes:
            size = imgui.calc_text_size(text, wrap_width=wrap)
            draw.add_rect_filled(imgui.ImVec2(origin.x + 6, y - 3), imgui.ImVec2(origin.x + 14 + size.x, y + size.y + 3),
                                 imgui.IM_COL32(0, 0, 0, 170), 4.0)
            draw.add_text(font, font_size, imgui.ImVec2(origin.x + 10, y), imgui.get_color_u32(COLOURS.get(level, COLOURS["info"])),
                          text, wrap)
            y += size.y + 10

    def _field(self, width: int, height: int) -> list[tuple[str, str]]:
        """The raw radiance field from this viewpoint, rendered in the background (see field_preview.py);
        what to say over it."""
        app, viewport, preview = self.app, self.app.viewport, self.app.field_preview
        update = app.state.viewing_update
        live = app.actions.live_refine_path()
        if live is not None:  # a refinement is running: its field as it fits, re-read whenever the file changes
            update = (live, live.stat().st_mtime_ns)
        if (live is None and update < 1) or app.world_from_capture is None:
            viewport.show_image(np.full((8, 8, 3), BACKDROP, np.float32), width, height)
            self._field_shown = None
            return [("The field appears after the first update.", "info")] if app.state.capture_dir is not None else []
        if viewport.dirty or self._field_size != (width, height, update):
            preview.request(app.state.capture_dir, live if live is not None else update, app.actions.checkpoint,
                            viewport.orbit.camera(width, height), app.world_from_capture)
            self._field_size = (width, height, update)
            viewport.dirty = False
        if preview.image is not None and preview.image_key != self._field_shown:
            viewport.show_image(preview.image, width, height)
            self._field_shown = preview.image_key
        notes = []
        if live is not None:
            notes.append(("refining: the field as it fits, refreshed every few seconds", "info"))
        elif preview.busy():
            notes.append(("rendering the field...", "info"))
        if preview.error:
            notes.append((preview.error, "error"))
        return notes

    def _mouse(self, width: int, height: int) -> None:
        if not imgui.is_item_hovered():
            return
        io = imgui.get_io()
        orbit = self.app.viewport.orbit
        dx, dy = io.mouse_delta.x, io.mouse_delta.y
        moved = False
        panning = imgui.is_mouse_down(imgui.MouseButton_.right) or (io.key_shift and (
            imgui.is_mouse_down(imgui.MouseButton_.left) or imgui.is_mouse_down(imgui.MouseButton_.middle)))
        if (dx or dy) and panning:
            orbit.pan(dx, dy, height)
            moved = True
        elif (dx or dy) and (imgui.is_mouse_down(imgui.MouseButton_.left) or imgui.is_mouse_down(imgui.MouseButton_.middle)):
            orbit.orbit(dx, dy)
            moved = True
        if io.mouse_wheel:
            orbit.zoom(io.mouse_wheel)
            moved = True
        if imgui.is_mouse_double_clicked(imgui.MouseButton_.left) or imgui.is_key_pressed(imgui.Key.f):
            orbit.frame(self.app.viewport.bounds)
            moved = True
        if moved:
            self.app.viewport.dirty = True

    def _guides(self, origin, width: int, height: int) -> None:
        viewport = self.app.viewport
        camera = viewport.orbit.camera(width, height)
        draw = imgui.get_window_draw_list()
        draw.push_clip_rect(imgui.ImVec2(origin.x, origin.y), imgui.ImVec2(origin.x + width, origin.y + height), True)
        draw_grid(draw, origin, camera, viewport.bounds, width, height)
        draw_axis_gizmo(draw, origin, camera, height)
        self.scale_label = draw_scale_bar(draw, origin, camera, viewport.orbit.target, width, height,
                                          metres=self._shown_in_metres())
        draw.pop_clip_rect()

    def _shown_in_metres(self) -> bool:
        """Whether the asset on screen was exported in metres (its file says so; read once per file)."""
        from lirm.engine.export.glb_placement import read_units

        path = self.app.state.preview_asset
        key = None if path is None or not path.is_file() else (str(path), path.stat().st_mtime_ns)
        if key != getattr(self, "_units_key", "unread"):
            self._units_key, self._in_metres = key, key is not None and read_units(path) == "metres"
        return self._in_metres

    def _frusta(self, origin, width: int, height: int) -> None:
        app = self.app
        draw = imgui.get_window_draw_list()
        depth = 0.25 * app.capture_scale
        sets = [(app.capture_cameras, INPUT_COLOUR)]
        if app.state.guidance:
            sets.append((app.suggested_cameras, SUGGESTED_COLOUR))
        # Every segment's ends projected in one call: a projection per segment rebuilt the view's camera
        # each time, and at the redraw rate of a running job that kept a core busy (README, "The app").
        for cameras, colour in sets:
            segments = [pair for camera in cameras for pair in frustum_lines(camera, app.world_from_capture, depth)]
            if not segments:
                continue
            xy, front = app.viewport.project(np.asarray(segments, np.float64).reshape(-1, 3), width, height)
            xy, front = xy.reshape(-1, 2, 2), front.reshape(-1, 2).all(axis=1)
            for (a, b), shown in zip(xy, front):
                if shown:
                    draw.add_line(imgui.ImVec2(origin.x + a[0], origin.y + a[1]), imgui.ImVec2(origin.x + b[0], origin.y + b[1]),
                                  colour, 1.5)
