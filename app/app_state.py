"""Everything the window shows, in one place: the open capture (the project), the views and their
status, the reconstruction history, the viewport and lighting settings, guidance, export settings,
running jobs and messages. Panels read it; only the action layer (actions.py) changes it.

The user's choices (views picked for the next update, viewport, lighting and export settings, the
update being looked at) are saved in the capture as app_state.json after every change, so reopening
the capture opens where it was. Paths in it that lie inside the capture are written relative to the
capture, so a copied or moved capture keeps working on its own files; absolute ones that an older
version wrote into another capture are re-based onto this one. Whatever the file holds, opening never
fails on it: each value that cannot be restored is dropped (the default is used) with a message.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from lirm.engine.io.atomic_files import atomic_write_json

log = logging.getLogger("lirm.app")
STATE_FILE = "app_state.json"
CHANNELS = ("beauty", "albedo", "roughness", "metallic", "normal", "field")
BUILTIN_ENVIRONMENTS = ("studio", "sky", "overcast")  # renderer/procedural_environments.py (checked by a test)
ENVIRONMENT_SUFFIXES = (".hdr", ".exr")


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
    show_guides: bool = True  # ground grid, axis gizmo, scale bar


@dataclass
class ExportSettings:
    path: str = ""  # default: <capture>/export/asset.glb
    faces: int = 20_000
    texture: int = 1024
    grid: int = 256  # the same default as `lirm export --grid`
    turntable_frames: int = 24
    fit_textures: bool = True  # a step refined with materials: its textures fitted to the photos (`lirm export`)


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
    # Refine inverse-renders the materials under the capture's lighting (`lirm refine --materials`):
    # the asset is for relighting, and a plain fit bakes the photos' shading into the albedo.
    refine_materials: bool = True
    # Refine carves the masks' hull where the photos see through it (a cup's opening) before the fit,
    # as `lirm refine` does by default; off: `--no-carve-openings`, the hull as the masks make it.
    refine_carve_openings: bool = True
    # Refine also holds the materials to what the image-space material network reads in each photo, when
    # its check says it knows them (`lirm refine`'s default, `--material-network auto`); off: `off`.
    refine_material_network: bool = True


@dataclass
class AppState:
    capture_dir: Path | None = None
    frames: list[FrameInfo] = field(default_factory=list)
    # (file name, why) of the files an import did not take, side files (notes, sidecars) left out
    skipped_files: list[tuple[str, str]] = field(default_factory=list)
    updates: list[dict] = field(default_factory=list)  # capture.json's update history
    choices: SavedChoices = field(default_factory=SavedChoices)
    weights: str = ""  # which weights the reconstruction used, and whether they are trained
    real_size: dict | None = None  # the object's stated height or width in metres (capture.json), None: arbitrary scale
    guidance: dict | None = None  # suggestions.json, once asked for
    coverage: dict | None = None  # surface_coverage.npz arrays
    messages: list[Message] = field(default_factory=list)
    last_export: Path | None = None
    preview_asset: Path | None = None  # the .glb the viewport shows
    update_costs: dict[int, tuple[float, float | None]] = field(default_factory=dict)  # update: (job seconds, peak MB)
    choices_restored: bool = False  # the choices came from the capture's app_state.json (dropped if they cannot be shown)

    def say(self, text: str, level: str = "info") -> None:
        self.messages.append(Message(level, text))
        del self.messages[:-100]
        getattr(log, "error" if level == "error" else "warning" if level == "warning" else "info")(text)

    @property
    def viewing_update(self) -> int:
        """The update the viewport shows (0: none yet)."""
        chosen = self.choices.viewing_update
        return len(self.updates) if chosen is None else max(0, min(chosen, len(self.updates)))

    # ---- paths: what the user sees is absolute, what the capture keeps is relative to it --------
    def capture_path(self, path: str | Path) -> Path:
        """A path typed by the user or read from the capture, made absolute: a relative one is in the capture."""
        p = Path(path).expanduser()
        return p if p.is_absolute() or self.capture_dir is None else self.capture_dir / p

    def _saved_form(self, path: str) -> str:
        """How a path is written into app_state.json: relative to the capture when it lies inside it."""
        if not path or self.capture_dir is None or path in BUILTIN_ENVIRONMENTS:
            return path
        p = self.capture_path(path)
        try:
            return p.relative_to(self.capture_dir).as_posix()
        except ValueError:
            return str(p)

    def _restored_path(self, saved: str, what: str, dropped: list[str]) -> str | None:
        """A path read from app_state.json, absolute; None when it cannot be used (the reason added to
        `dropped`). An absolute path inside another capture (the file of a copied or moved capture,
        written by a version that saved absolute paths) is re-based onto this capture."""
        p = Path(saved).expanduser()
        if not p.is_absolute():
            return str(self.capture_dir / p)
        try:
            p.relative_to(self.capture_dir)
            return str(p)
        except ValueError:
            pass
        owner = next((a for a in p.parents if (a / "capture.json").is_file()), None)
        if owner is not None:
            rebased = self.capture_dir / p.relative_to(owner)
            if owner.resolve() != self.capture_dir:  # (not this capture under another name, e.g. through a link)
                self.say(f"the saved {what} {p} was inside another capture ({owner}); it is now {rebased}", "warning")
            return str(rebased)
        if not p.parent.is_dir():
            dropped.append(f"{what} {p} (its folder no longer exists)")
            return None
        return str(p)

    def save_choices(self) -> None:
        if self.capture_dir is None:
            return
        data = asdict(self.choices)
        data["view"]["environment"] = self._saved_form(data["view"]["environment"])
        data["export"]["path"] = self._saved_form(data["export"]["path"])
        try:
            atomic_write_json(self.capture_dir / STATE_FILE, data)
        except OSError as err:  # a read-only capture still opens; the choices just are not kept
            self.say(f"could not save the window's state in {self.capture_dir}: {err}", "warning")

    def load_choices(self) -> None:
        """The choices saved in the capture; each value that cannot be restored is dropped with a message."""
        self.choices_restored = False
        path = None if self.capture_dir is None else self.capture_dir / STATE_FILE
        if path is None or not path.is_file():
            self.choices = SavedChoices()
            return
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            if not isinstance(data, dict):
                raise ValueError(f"a JSON object was expected, not {type(data).__name__}")
        except (OSError, ValueError) as err:
            self.say(f"{path} is damaged ({err}); starting with default settings (the file is left as it is)", "warning")
            self.choices = SavedChoices()
            return
        dropped: list[str] = []
        self.choices = self._restore(data, dropped)
        self.choices_restored = True
        if dropped:
            self.say(f"some of the window's saved state in {path} could not be restored and was dropped (defaults used): "
                     + "; ".join(dropped), "warning")

    def _restore(self, data: dict, dropped: list[str]) -> SavedChoices:
        defaults = SavedChoices()
        out = SavedChoices()

        def take(section: dict, key: str, name: str, check, default):
            """section[key] if `check` accepts it (returning the value to use, or raising ValueError/TypeError
            with the reason), else the default; unknown keys are ignored, missing ones get the default."""
            if key not in section:
                return default
            try:
                return check(section[key])
            except (ValueError, TypeError) as err:
                dropped.append(f"{name} {section[key]!r} ({err})")
                return default

        out.selected = take(data, "selected", "picked views", _str_list, defaults.selected)
        out.viewing_update = take(data, "viewing_update", "update looked at", _optional_count, defaults.viewing_update)
        out.auto_update = take(data, "auto_update", "automatic updates", _bool, defaults.auto_update)
        out.refine_minutes = take(data, "refine_minutes", "refinement minutes", _positive_number, defaults.refine_minutes)
        out.refine_materials = take(data, "refine_materials", "refinement of the materials", _bool, defaults.refine_materials)
        out.refine_carve_openings = take(data, "refine_carve_openings", "carving of openings", _bool,
                                         defaults.refine_carve_openings)
        out.refine_material_network = take(data, "refine_material_network", "the material network", _bool,
                                           defaults.refine_material_network)
        view = take(data, "view", "viewport settings", _section, {})
        v, dv = out.view, defaults.view
        v.channel = take(view, "channel", "viewport channel", lambda x: _one_of(x, CHANNELS), dv.channel)
        v.environment = take(view, "environment", "environment", lambda x: self._environment(x, dropped), dv.environment)
        v.rotation_deg = take(view, "rotation_deg", "environment rotation", lambda x: _number(x) % 360.0, dv.rotation_deg)
        v.exposure_ev = take(view, "exposure_ev", "exposure", lambda x: _number(x, -20.0, 20.0), dv.exposure_ev)
        v.background = take(view, "background", "background switch", _bool, dv.background)
        v.show_cameras = take(view, "show_cameras", "cameras switch", _bool, dv.show_cameras)
        v.show_coverage = take(view, "show_coverage", "coverage switch", _bool, dv.show_coverage)
        v.show_guides = take(view, "show_guides", "guides switch", _bool, dv.show_guides)
        export = take(data, "export", "export settings", _section, {})
        e, de = out.export, defaults.export

        def export_path(x) -> str:
            text = _str(x)
            return (self._restored_path(text, "export path", dropped) or "") if text else ""

        e.path = take(export, "path", "export path", export_path, de.path)
        e.faces = take(export, "faces", "export faces", lambda x: _count(x, 100, 10_000_000), de.faces)
        e.texture = take(export, "texture", "texture side", lambda x: _count(x, 16, 16384), de.texture)
        e.grid = take(export, "grid", "export grid", lambda x: _count(x, 16, 2048), de.grid)
        e.turntable_frames = take(export, "turntable_frames", "turntable frames", lambda x: _count(x, 1, 3600), de.turntable_frames)
        e.fit_textures = take(export, "fit_textures", "texture fit switch", _bool, de.fit_textures)
        return out

    def _environment(self, value, dropped: list[str]) -> str:
        name = _str(value)
        if name in BUILTIN_ENVIRONMENTS:
            return name
        if Path(name).suffix.lower() not in ENVIRONMENT_SUFFIXES:
            raise ValueError(f"neither a built-in environment ({', '.join(BUILTIN_ENVIRONMENTS)}) nor an .hdr/.exr file")
        path = self._restored_path(name, "environment", dropped)
        if path is None:
            return SavedChoices().view.environment
        if not Path(path).is_file():
            raise ValueError(f"{path} is not there any more")
        return path


def _str(x) -> str:
    if not isinstance(x, str):
        raise TypeError(f"text was expected, not {type(x).__name__}")
    return x


def _str_list(x) -> list[str]:
    if not isinstance(x, list) or not all(isinstance(i, str) for i in x):
        raise TypeError("a list of view names was expected")
    return list(x)


def _bool(x) -> bool:
    if not isinstance(x, bool):
        raise TypeError("true or false was expected")
    return x


def _number(x, low: float = -math.inf, high: float = math.inf) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
        raise TypeError("a finite number was expected")
    if not low <= x <= high:
        raise ValueError(f"outside {low:g}..{high:g}")
    return float(x)


def _positive_number(x) -> float:
    if _number(x) <= 0:
        raise ValueError("a positive number was expected")
    return float(x)


def _count(x, low: int, high: int) -> int:
    if isinstance(x, bool) or not isinstance(x, int):
        raise TypeError("a whole number was expected")
    if not low <= x <= high:
        raise ValueError(f"outside {low}..{high}")
    return x


def _optional_count(x) -> int | None:
    return None if x is None else _count(x, 0, 1_000_000)


def _section(x) -> dict:
    if not isinstance(x, dict):
        raise TypeError("a JSON object was expected")
    return x


def _one_of(x, allowed: tuple[str, ...]) -> str:
    if x not in allowed:
        raise ValueError(f"not one of {', '.join(allowed)}")
    return x
