"""Lighting: the built-in environments and the user's HDRIs, rotation, exposure, background."""

from __future__ import annotations

from imgui_bundle import imgui

from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS


class LightingPanel:
    title = "Lighting"

    def __init__(self, app):
        self.app = app
        self.hdri_path = ""

    def draw(self) -> None:
        state, actions = self.app.state, self.app.actions
        view = state.choices.view
        choices = list(PROCEDURAL_ENVIRONMENTS) + [p for p in self.app.user_environments if p not in PROCEDURAL_ENVIRONMENTS]
        if imgui.begin_combo("environment", view.environment.split("/")[-1]):
            for name in choices:
                if imgui.selectable(name.split("/")[-1], name == view.environment)[0]:
                    actions.set_environment(name)
            imgui.end_combo()
        imgui.set_next_item_width(-110)
        _, self.hdri_path = imgui.input_text("##hdri", self.hdri_path)
        imgui.same_line()
        if imgui.button("Add HDRI"):
            self.app.add_environment(self.hdri_path)
        changed, rotation = imgui.slider_float("rotation", view.rotation_deg, 0.0, 360.0, "%.0f°")
        if changed:
            actions.set_rotation(rotation)
        changed, exposure = imgui.slider_float("exposure", view.exposure_ev, -4.0, 4.0, "%.1f EV")
        if changed:
            actions.set_exposure(exposure)
        changed, background = imgui.checkbox("show the environment behind", view.background)
        if changed:
            actions.set_background(background)
