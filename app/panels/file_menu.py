"""The File menu: New project from photos, Open capture, Add photos, Recent, the demo capture.

Paths come from native dialogs (file_dialogs.py) where the system has them, else from a small
popup where the path is typed (the same the Capture panel's field takes)."""

from __future__ import annotations

from pathlib import Path

from imgui_bundle import imgui

from .. import file_dialogs
from ..recent import recent_captures

ASKS = {
    "new": ("New project from photos", "The folder of photos (or a video file) to make a new capture from:", "folder"),
    "open": ("Open capture", "The capture folder (made by `lirm capture` or this app):", "folder"),
    "add": ("Add photos", "The folder of photos to add to the open capture:", "folder"),
}


class FileMenu:
    def __init__(self, app):
        self.app = app
        self.pending = None  # a native dialog under way
        self.asking: str | None = None  # the typed-path popup's purpose
        self.typed = ""

    def draw_menu(self) -> None:
        """Inside the main menu bar."""
        actions, state = self.app.actions, self.app.state
        if not imgui.begin_menu("File"):
            return
        if imgui.menu_item("New project from photos...", "Ctrl+N", False)[0]:
            self.ask("new")
        if imgui.menu_item("Open capture...", "Ctrl+O", False)[0]:
            self.ask("open")
        if imgui.menu_item("Add photos...", "", False, state.capture_dir is not None)[0]:
            self.ask("add")
        if imgui.begin_menu("Recent", bool(recent_captures())):
            for path in recent_captures():
                if imgui.menu_item(path.name, str(path.parent), state.capture_dir == path)[0]:
                    actions.open_capture(path)
            imgui.end_menu()
        imgui.separator()
        if imgui.menu_item("Demo capture", "", False)[0]:
            actions.open_demo_capture()
        imgui.end_menu()

    def ask(self, purpose: str) -> None:
        title, _, kind = ASKS[purpose]
        if file_dialogs.available():
            start = str(self.app.state.capture_dir.parent) if self.app.state.capture_dir else str(Path.home())
            self.pending = file_dialogs.PendingDialog(kind, title, lambda path: self.chosen(purpose, path), start)
        else:
            self.asking, self.typed = purpose, ""

    def chosen(self, purpose: str, path: str) -> None:
        actions = self.app.actions
        if purpose == "new":
            actions.new_project(path)
        elif purpose == "open":
            actions.open_capture(path)
        elif purpose == "add":
            actions.add_photos(path)

    def draw_dialogs(self) -> None:
        """Every frame: poll a native dialog, or show the typed-path popup."""
        if self.pending is not None and self.pending.poll():
            self.pending = None
        if self.asking is None:
            return
        title, prompt, _ = ASKS[self.asking]
        imgui.open_popup(title)
        if imgui.begin_popup_modal(title, None, imgui.WindowFlags_.always_auto_resize)[0]:
            imgui.text(prompt)
            imgui.text_disabled("(no file dialog program here: zenity or kdialog gives one)")
            imgui.set_next_item_width(480)
            entered, self.typed = imgui.input_text("##path", self.typed, imgui.InputTextFlags_.enter_returns_true)
            if (imgui.button("OK") or entered) and self.typed.strip():
                purpose, self.asking = self.asking, None
                imgui.close_current_popup()
                self.chosen(purpose, self.typed.strip())
            imgui.same_line()
            if imgui.button("Cancel"):
                self.asking = None
                imgui.close_current_popup()
            imgui.end_popup()
