"""Messages: what happened, errors in red with what to do, newest last."""

from __future__ import annotations

import time

from imgui_bundle import imgui

from .common import coloured


class LogPanel:
    title = "Messages"

    def __init__(self, app):
        self.app = app
        self._seen = 0

    def draw(self) -> None:
        messages = self.app.state.messages
        for m in messages:
            coloured(f"{time.strftime('%H:%M:%S', time.localtime(m.at))}  {m.text}", m.level)
        if len(messages) != self._seen:
            imgui.set_scroll_here_y(1.0)
            self._seen = len(messages)
