"""Export: the glTF with its settings, and a turntable image sequence of it."""

from __future__ import annotations

from imgui_bundle import imgui

from .common import job_progress


class ExportPanel:
    title = "Export"

    def __init__(self, app):
        self.app = app
        self._typing: str | None = None  # the path box's text while it is being edited
        self._height_cm: float | None = None  # the height box's value (from the capture when it has one)

    def draw(self) -> None:
        app, state, actions = self.app, self.app.state, self.app.actions
        settings = state.choices.export
        if state.capture_dir is None:
            imgui.text("Open a capture to export it.")
            return
        default = str(actions.default_export_path())
        imgui.set_next_item_width(-1)
        changed, typed = imgui.input_text("##export_path", self._typing if self._typing is not None else settings.path or default)
        if changed:  # the default is not written down: a copied capture exports into itself
            self._typing = typed
            settings.path = "" if typed.strip() in ("", default) else typed
        if not imgui.is_item_active():
            self._typing = None  # an emptied box shows the default again once left
        if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
            imgui.set_tooltip(f"{state.capture_path(settings.path or default)}\n(a relative path is inside the capture)")
        self._real_size(state, actions)
        _, settings.faces = imgui.input_int("faces", settings.faces, 1000)
        _, settings.texture = imgui.input_int("texture side", settings.texture, 256)
        _, settings.grid = imgui.input_int("grid", settings.grid, 32)
        _, settings.fit_textures = imgui.checkbox("fit textures to the photos", settings.fit_textures)
        if imgui.is_item_hovered(imgui.HoveredFlags_.for_tooltip):
            imgui.set_tooltip("For a step refined with materials (Refine with materials on): after baking, the textures are\n"
                              "fitted to the photos under the fitted lighting (sharper labels and fine detail; about half a\n"
                              "minute on this CPU). Other steps export their baked textures either way.")
        running = app.jobs.running("export")
        imgui.begin_disabled(bool(running) or not state.updates)
        if imgui.button(f"Export glTF (update {max(1, state.viewing_update)})"):
            actions.export()
        app.note_widget("export")
        imgui.end_disabled()
        imgui.same_line()
        if imgui.button("Turntable images"):
            actions.export_turntable()
        for job in running + app.jobs.running("render"):
            job_progress(job, app.jobs.cancel)
        if state.last_export:
            imgui.text_wrapped(f"last export: {state.last_export}")

    def _real_size(self, state, actions) -> None:
        """The object's real height, so that the glb is in metres (without it the scale is arbitrary)."""
        if state.real_size:
            which, metres = next(iter(state.real_size.items()))
            imgui.text(f"real {which}: {100 * metres:.1f} cm (the glb is in metres)")
        else:
            imgui.text_colored(imgui.ImVec4(1.0, 0.8, 0.3, 1.0), "scale: arbitrary (the photos' units)")
        if self._height_cm is None:
            self._height_cm = 100 * next(iter(state.real_size.values())) if state.real_size else 10.0
        imgui.set_next_item_width(120)
        _, self._height_cm = imgui.input_float("object height (cm)", self._height_cm, 0.5, 5.0, "%.1f")
        imgui.same_line()
        if imgui.button("Set size"):
            actions.set_real_size(self._height_cm / 100.0)
