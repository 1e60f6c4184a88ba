"""Capture: open a capture, import photos or a video, the views with their pose and mask status,
and which of them go into the next update."""

from __future__ import annotations

from imgui_bundle import imgui

from .common import coloured, job_progress


class CapturePanel:
    title = "Capture"

    def __init__(self, app):
        self.app = app
        self.path = ""

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
            imgui.text_wrapped("No capture open. Open a folder made by `lirm capture`, import photos, or start from the demo capture.")
            return
        imgui.text_wrapped(str(state.capture_dir))
        posed = sum(f.posed for f in state.frames)
        imgui.text(f"{len(state.frames)} photos, {posed} posed; next update: {', '.join(actions.next_views()) or 'none left'}")
        if imgui.small_button("Clear picks"):
            actions.select_views([])
        imgui.same_line()
        if imgui.small_button("Pick unused"):
            used = {f for u in state.updates for f in u["frames"]}
            actions.select_views([f.frame_id for f in state.frames if f.prepared and f.frame_id not in used])
        flags = imgui.TableFlags_.borders_inner_h | imgui.TableFlags_.scroll_y | imgui.TableFlags_.row_bg
        if imgui.begin_table("views", 5, flags, imgui.ImVec2(0, 0)):
            for name in ("use", "view", "pose", "mask", "update"):
                imgui.table_setup_column(name)
            imgui.table_headers_row()
            for f in state.frames:
                imgui.table_next_row()
                imgui.table_next_column()
                if f.prepared:
                    changed, _ = imgui.checkbox(f"##pick_{f.frame_id}", f.frame_id in state.choices.selected)
                    if changed:
                        actions.toggle_view(f.frame_id)
                imgui.table_next_column()
                imgui.text(f.name)
                imgui.table_next_column()
                coloured("posed" if f.posed else f.pose_status, "ok" if f.posed else "warning")
                imgui.table_next_column()
                coloured(f.mask_status, "ok" if f.mask_status == "ok" else "warning")
                imgui.table_next_column()
                imgui.text("" if f.update is None else str(f.update))
            imgui.end_table()
