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
        imgui.push_text_wrap_pos(0.0)  # wrap at the panel's edge: errors carry the whole advice
        for m in messages:
            coloured(f"{time.strftime('%H:%M:%S', time.localtime(m.at))}  {m.text}", m.level)
        imgui.pop_text_wrap_pos()
        if len(messages) != self._seen:
            imgui.set_scroll_here_y(1.0)
            self._seen = len(messages)
