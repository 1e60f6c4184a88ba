"""Lighting: the capture's own lighting ("as photographed", estimated from its photos' backgrounds),
the built-in environments and the user's HDRIs, rotation, exposure, background."""

from __future__ import annotations

import json
from pathlib import Path

from imgui_bundle import imgui

from lirm.engine.lighting.capture_lighting import INFO_FILE, LIGHTING_FOLDER, PANORAMA_FILE, PICTURE_FILE, missing_lighting_reason
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS

AS_PHOTOGRAPHED = "as photographed"


class LightingPanel:
    title = "Lighting"

    def __init__(self, app):
        self.app = app
        self.hdri_path = ""
        self._reason_key, self._reason = None, ""  # missing_lighting_reason, kept per capture.json version

    def draw(self) -> None:
        state, actions = self.app.state, self.app.actions
        view = state.choices.view
        photographed = self.as_photographed_path()
        own = [str(photographed)] if photographed else []
        choices = own + list(PROCEDURAL_ENVIRONMENTS) + [p for p in self.app.user_environments if p not in PROCEDURAL_ENVIRONMENTS and p not in own]

        def label(name: str) -> str:
            return AS_PHOTOGRAPHED if name in own else name.split("/")[-1]

        if imgui.begin_combo("environment", label(view.environment)):
            for name in choices:
                if imgui.selectable(label(name), name == view.environment)[0]:
                    actions.set_environment(name)
            imgui.end_combo()
        if view.environment in own:
            self._draw_panorama(photographed.parent)
        elif photographed is None and state.capture_dir is not None:
            reason = self._missing_reason(state.capture_dir)
            imgui.text_wrapped(f"No \"{AS_PHOTOGRAPHED}\" lighting: {reason}. The environments here still light it; "
                               "a refinement fits the materials only under a lighting estimate.")
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

    def _missing_reason(self, capture_dir) -> str:
        """Why the capture has no lighting estimate, read once per capture.json version."""
        path = Path(capture_dir) / "capture.json"
        try:
            key = (str(path), path.stat().st_mtime_ns)
        except OSError:
            return "its capture.json cannot be read"
        if self._reason_key != key:
            self._reason_key, self._reason = key, missing_lighting_reason(Path(capture_dir))
        return self._reason

    def as_photographed_path(self) -> Path | None:
        """The open capture's lighting estimate, when it has one."""
        capture = self.app.state.capture_dir
        path = None if capture is None else Path(capture) / LIGHTING_FOLDER / PANORAMA_FILE
        return path.resolve() if path is not None and path.is_file() else None

    def _draw_panorama(self, folder: Path) -> None:
        texture = self.app.picture_texture(folder / PICTURE_FILE)
        if texture is not None:
            width = imgui.get_content_region_avail().x
            imgui.image(imgui.ImTextureRef(texture.glo), imgui.ImVec2(width, width / 2))
        try:
            info = json.loads((folder / INFO_FILE).read_text())
        except (OSError, ValueError):
            info = {}
        seen = info.get("seen_fraction")
        imgui.text_wrapped(f"estimated from the backgrounds of {info.get('photos_used', '?')} photos; "
                           + (f"{100 * seen:.0f}% of directions seen, " if seen is not None else "")
                           + "the hatched rest is filled smoothly, not measured")
        if (info.get("config") or {}).get("response") == "srgb":
            imgui.text_wrapped("The photos were read through a plain sRGB curve (a plain backdrop photographed "
                               "clipped), and under this light the viewport shows them so.")
