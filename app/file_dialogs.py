"""Native file dialogs (imgui-bundle's portable-file-dialogs) that never block the window.

A dialog runs as its own helper process (zenity, kdialog, ... on Linux); the window polls it every
frame and calls back with the chosen path. Where no dialog program exists (a bare server, Xvfb in
CI) `available()` is False and the File menu asks for the path in a small typed-path popup instead.
"""

from __future__ import annotations

import shutil
from typing import Callable

LINUX_BACKENDS = ("zenity", "kdialog", "qarma", "matedialog")


def available() -> bool:
    return any(shutil.which(name) for name in LINUX_BACKENDS)


class PendingDialog:
    def __init__(self, kind: str, title: str, on_result: Callable[[str], None], start: str = ""):
        from imgui_bundle import portable_file_dialogs as pfd

        self.on_result = on_result
        self.dialog = pfd.select_folder(title, start) if kind == "folder" else pfd.open_file(title, start)

    def poll(self) -> bool:
        """True once the dialog is closed (and the callback called with the choice, if any)."""
        if not self.dialog.ready(0):
            return False
        result = self.dialog.result()
        chosen = result[0] if isinstance(result, list) and result else result if isinstance(result, str) else ""
        if chosen:
            self.on_result(chosen)
        return True
