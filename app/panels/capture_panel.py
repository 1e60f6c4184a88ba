"""Capture: open a capture, import photos or a video, the views with their pose and mask status,
and which of them go into the next update."""

from __future__ import annotations

from imgui_bundle import imgui

from .common import coloured, job_progress, short_status


class CapturePanel:
    title = "Capture"

    def __init__(self, app):
        self.app = app
        self.path = ""
        self.inspected: str | None = None  # the view shown below the table, for a mask fix
        self.box: list[float] | None = None  # drawn box, in the shown image's pixels
        self._drag_from = None

    def draw(self) -> None:
        app, state, actions = self.app, self.app.state, self.app.actions
        imgui.text("Capture folder, photo folder or video:")
        imgui.set_next_item_width(-1)
        _, self.path = imgui.input_text("##capture_path", self.path)
        if imgui.button("Open capture"):
            actions.open_capture(self.path)
        imgui.same_line()
        if imgui.button("Import photos / video"):
            actions.import_photos(self.path) if self.path else state.say("type the folder of photos or the video first", "warning")
        imgui.same_line()
        if imgui.button("Demo capture"):
            actions.open_demo_capture()
        for job in app.jobs.running("capture"):
            job_progress(job, app.jobs.cancel)
        imgui.separator()
        if state.capture_dir is None:
            making = app.jobs.running("capture")
            if making:  # e.g. `lirm app --demo` building its capture: say what is happening, not "nothing"
                imgui.text_wrapped(f"{making[0].title}: it opens here when it is ready.")
            else:
                imgui.text_wrapped("No capture open. Use File > New project from photos or Open capture (or the "
                                   "field above), or start from the demo capture.")
            return
        imgui.text_wrapped(str(state.capture_dir))
        posed = sum(f.posed for f in state.frames)
        imgui.text_wrapped(f"{len(state.frames)} photos, {posed} posed; next update: {', '.join(actions.next_views()) or 'none left'}")
        if state.skipped_files:
            self._skipped_files(state.skipped_files)
        if imgui.small_button("Clear picks"):
            actions.select_views([])
        imgui.same_line()
        if imgui.small_button("Pick unused"):
            used = {f for u in state.updates for f in u["frames"]}
            actions.select_views([f.frame_id for f in state.frames if f.prepared and f.frame_id not in used])
        flags = imgui.TableFlags_.borders_inner_h | imgui.TableFlags_.scroll_y | imgui.TableFlags_.row_bg
        # The table scrolls; with a view opened for its mask, it leaves room for the mask editor below it
        # (which was drawn under the panel's visible part).
        table_height = 0.0
        if self.inspected is not None:
            avail = imgui.get_content_region_avail()
            editor = min(avail.x * 0.75, 0.55 * avail.y) + 3.5 * imgui.get_frame_height_with_spacing()  # the image, a line, buttons
            table_height = max(4.0 * imgui.get_frame_height_with_spacing(), avail.y - editor)
        if imgui.begin_table("views", 6, flags, imgui.ImVec2(0, table_height)):
            # The name takes the room left; the other columns fit their content (names are cut at the
            # panel's edge, their tooltip has them whole).
            fixed, stretch = imgui.TableColumnFlags_.width_fixed, imgui.TableColumnFlags_.width_stretch
            for name, flags in (("use", fixed), ("", fixed), ("view", stretch), ("pose", fixed), ("mask", fixed), ("update", fixed)):
                imgui.table_setup_column(name, flags)
            imgui.table_headers_row()
            for f in state.frames:
                imgui.table_next_row()
                imgui.table_next_column()
                if f.prepared:
                    changed, _ = imgui.checkbox(f"##pick_{f.frame_id}", f.frame_id in state.choices.selected)
                    if changed:
                        actions.toggle_view(f.frame_id)
                imgui.table_next_column()
                thumbnail = app.thumbnail_texture(f.frame_id) if f.prepared else None
                if thumbnail is not None:
                    imgui.image(imgui.ImTextureRef(thumbnail.glo), imgui.ImVec2(28, 28))
                imgui.table_next_column()
                if imgui.selectable(f"{f.name}##row_{f.frame_id}", self.inspected == f.frame_id)[0]:
                    self.inspected, self.box = f.frame_id, None
                app.note_widget(f"view_{f.frame_id}")
                if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
                    used = "not used yet" if f.update is None else f"used by update {f.update}"
                    imgui.set_tooltip(f"{f.name}\nview {f.frame_id}; pose: {'posed' if f.posed else f.pose_status}; "
                                      f"mask: {f.mask_status}; {used}\n(click to see its mask and redo it with a box)")
                imgui.table_next_column()
                pose = "posed" if f.posed else f.pose_status
                coloured(("posed" if f.posed else short_status(pose) or "not posed"), "ok" if f.posed else "warning")
                _whole_on_hover(f.name, "pose", pose)
                imgui.table_next_column()
                coloured(short_status(f.mask_status) or "not usable", "ok" if f.mask_status == "ok" else "warning")
                _whole_on_hover(f.name, "mask", f.mask_status)
                imgui.table_next_column()
                imgui.text("" if f.update is None else str(f.update))
            imgui.end_table()
        if self.inspected is not None:
            self._inspect(self.inspected)

    def _skipped_files(self, skipped: list[tuple[str, str]]) -> None:
        """The files the imports did not take, each with why (folded by default: a RAW + JPEG folder
        names every raw file)."""
        label = f"{len(skipped)} file{'s' if len(skipped) > 1 else ''} not imported##skipped_files"
        opened = imgui.tree_node(label)
        self.app.note_widget("skipped_files")
        if opened:
            for name, why in skipped:
                coloured(name, "warning")
                imgui.same_line()
                imgui.text_wrapped(why)
            imgui.tree_pop()

    def _inspect(self, frame_id: str) -> None:
        """The view with its mask tinted; drag a box round the object and fix the mask with it."""
        app = self.app
        shown = app.mask_overlay_texture(frame_id)
        if shown is None:
            return
        texture, scale = shown
        imgui.separator()
        if imgui.small_button("Close"):
            self.inspected, self.box = None, None
            return
        imgui.same_line()
        imgui.text(f"{frame_id}: drag a box round the object to redo its mask")
        avail = imgui.get_content_region_avail()
        room = max(avail.y - 2.0 * imgui.get_frame_height_with_spacing(), 60.0)  # the image fits above the button
        width = min(avail.x, room * texture.width / texture.height)
        height = width * texture.height / texture.width
        origin = imgui.get_cursor_screen_pos()
        imgui.image(imgui.ImTextureRef(texture.glo), imgui.ImVec2(width, height))
        to_image = texture.width / width  # window pixels -> shown image pixels
        if imgui.is_item_hovered() and imgui.is_mouse_clicked(imgui.MouseButton_.left):
            p = imgui.get_mouse_pos()
            self._drag_from = ((p.x - origin.x) * to_image, (p.y - origin.y) * to_image)
        if self._drag_from is not None:
            p = imgui.get_mouse_pos()
            x, y = (p.x - origin.x) * to_image, (p.y - origin.y) * to_image
            self.box = [min(self._drag_from[0], x), min(self._drag_from[1], y), max(self._drag_from[0], x), max(self._drag_from[1], y)]
            if not imgui.is_mouse_down(imgui.MouseButton_.left):
                self._drag_from = None
        if self.box is not None:
            a = imgui.ImVec2(origin.x + self.box[0] / to_image, origin.y + self.box[1] / to_image)
            b = imgui.ImVec2(origin.x + self.box[2] / to_image, origin.y + self.box[3] / to_image)
            imgui.get_window_draw_list().add_rect(a, b, imgui.IM_COL32(255, 220, 60, 255), 0.0, 0, 2.0)
            if imgui.button("Fix the mask with this box"):
                app.actions.fix_mask_with_box(frame_id, tuple(v / scale for v in self.box))
                self.box = None


def _whole_on_hover(name: str, what: str, status: str) -> None:
    """The cell shows a status's head; hovering it gives the whole reason."""
    if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
        imgui.set_tooltip(f"{name}\n{what}: {status}")
