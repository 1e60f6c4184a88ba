"""Everything the window shows, in one place: the open capture (the project), the views and their
status, the reconstruction history, the viewport and lighting settings, guidance, export settings,
running jobs and messages. Panels read it; only the action layer (actions.py) changes it.

The user's choices (views picked for the next update, viewport, lighting and export settings, the
update being looked at) are saved in the capture as app_state.json after every change, so reopening
the capture opens where it was.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from lirm.engine.io.atomic_files import atomic_write_json

log = logging.getLogger("lirm.app")
STATE_FILE = "app_state.json"


@dataclass
class FrameInfo:
    frame_id: str
    name: str
    posed: bool
    pose_status: str
    mask_status: str
    prepared: bool
    update: int | None  # the update that used it


@dataclass
class ViewSettings:
    channel: str = "beauty"  # beauty | albedo | roughness | metallic | normal | field
    environment: str = "studio"  # a built-in name or an .hdr/.exr path
    rotation_deg: float = 0.0
    exposure_ev: float = 0.0
    background: bool = True
    show_cameras: bool = True
    show_coverage: bool = False


@dataclass
class ExportSettings:
    path: str = ""  # default: <capture>/export/asset.glb
    faces: int = 20_000
    texture: int = 1024
    grid: int = 192
    turntable_frames: int = 24


@dataclass
class Message:
    level: str  # info | warning | error
    text: str
    at: float = field(default_factory=time.time)


@dataclass
class SavedChoices:
    """What app_state.json holds."""

    selected: list[str] = field(default_factory=list)
    viewing_update: int | None = None  # None: the latest
    view: ViewSettings = field(default_factory=ViewSettings)
    export: ExportSettings = field(default_factory=ExportSettings)
    auto_update: bool = False
    refine_minutes: float = 3.0


@dataclass
class AppState:
    capture_dir: Path | None = None
    frames: list[FrameInfo] = field(default_factory=list)
    updates: list[dict] = field(default_factory=list)  # capture.json's update history
    choices: SavedChoices = field(default_factory=SavedChoices)
    weights: str = ""  # which weights the reconstruction used, and whether they are trained
    guidance: dict | None = None  # suggestions.json, once asked for
    coverage: dict | None = None  # surface_coverage.npz arrays
    messages: list[Message] = field(default_factory=list)
    last_export: Path | None = None
    preview_asset: Path | None = None  # the .glb the viewport shows
    update_costs: dict[int, tuple[float, float | None]] = field(default_factory=dict)  # update: (job seconds, peak MB)

    def say(self, text: str, level: str = "info") -> None:
        self.messages.append(Message(level, text))
        del self.messages[:-100]
        getattr(log, "error" if level == "error" else "warning" if level == "warning" else "info")(text)

    @property
    def viewing_update(self) -> int:
        """The update the viewport shows (0: none yet)."""
        chosen = self.choices.viewing_update
        return len(self.updates) if chosen is None else max(0, min(chosen, len(self.updates)))

    def save_choices(self) -> None:
        if self.capture_dir is None:
            return
        try:
            atomic_write_json(self.capture_dir / STATE_FILE, asdict(self.choices))
        except OSError as err:  # a read-only capture still opens; the choices just are not kept
            self.say(f"could not save the window's state in {self.capture_dir}: {err}", "warning")

    def load_choices(self) -> None:
        path = None if self.capture_dir is None else self.capture_dir / STATE_FILE
        if path is None or not path.is_file():
            self.choices = SavedChoices()
            return
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            self.choices = SavedChoices(
                selected=list(data.get("selected", [])), viewing_update=data.get("viewing_update"),
                view=ViewSettings(**data.get("view", {})), export=ExportSettings(**data.get("export", {})),
                auto_update=bool(data.get("auto_update", False)), refine_minutes=float(data.get("refine_minutes", 3.0)))
        except (ValueError, TypeError) as err:
            self.say(f"{path} is damaged ({err}); starting with default settings (the file is left as it is)", "warning")
            self.choices = SavedChoices()
