"""Guidance: where to shoot next, how much of the object is covered, the view-sphere heat map."""

from __future__ import annotations

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
        imgui.text(f"surface: {g['surface']}")
        imgui.text(f"covered now {100 * g['coverage_now']:.0f}%, after these shots {100 * g['coverage_after']:.0f}%")
        for note in g.get("notes", []):
            imgui.text_wrapped(f"note: {note}")
        for s in g["suggestions"]:
            imgui.bullet_text(f"{s['rank']}. {s['sentence']} (azimuth {s['azimuth_deg']:.0f}°, elevation "
                              f"{s['elevation_deg']:.0f}°, +{100 * s['gain']:.0f}%)")
        texture = app.image_texture(state.capture_dir / "guidance" / "heat_map.png")
        if texture is not None:
            width = imgui.get_content_region_avail().x
            imgui.image(imgui.ImTextureRef(texture.glo), imgui.ImVec2(width, width * texture.height / texture.width))
