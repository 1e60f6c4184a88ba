"""`lirm app`: one window with docked panels (Capture, Reconstruct, Viewport, Lighting, Guidance,
Export, Messages), built on imgui-bundle's runner with moderngl drawing the viewport.

The window never waits on work: posing, updates, guidance and export run as `lirm` jobs (jobs.py),
polled once per frame. Closing the window while a job runs asks first; an export already under way
finishes on its own even if the app quits, and everything the user made lives in the capture folder.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .actions import AppActions
from .app_state import AppState
from .jobs import JobRunner
from .panels.capture_panel import CapturePanel
from .panels.export_panel import ExportPanel
from .panels.guidance_panel import GuidancePanel
from .panels.lighting_panel import LightingPanel
from .panels.log_panel import LogPanel
from .panels.reconstruct_panel import ReconstructPanel
from .panels.viewport_panel import ViewportPanel

log = logging.getLogger("lirm.app")

# Redraws a second when nothing happens (input wakes the window at once) and while work runs. Every
# frame redraws the whole window, about 150 ms of CPU on a software GL (llvmpipe, 2 cores): at 10 a
# second while a refinement ran, the window took the cores from it (74 steps in its 30 s at 5, 164 at 2:
# README, "The app"). Twice a second still shows the progress; input draws at full rate.
IDLE_FPS = 0.25
WORKING_FPS = 2.0


@dataclass(frozen=True)
class AppConfig:
    capture: Path | None = None
    demo: bool = False  # open the built-in demo capture (made once, in the background)
    reopen_last: bool = True  # with no capture named: the one open last time (an empty project otherwise)
    width: int = 1280
    height: int = 800
    checkpoint: Path | None = None
    script: Path | None = None  # steps run between frames (tests, recorded sessions): see script.py
    environment_width: int = 512  # built-in environments are rendered at this width
    extra_environments: tuple[str, ...] = field(default_factory=tuple)  # HDRI files offered besides the built-ins


class LirmApp:
    def __init__(self, config: AppConfig = AppConfig()):
        self.config = config
        self.state = AppState()
        self.jobs = JobRunner()
        self.actions = AppActions(self.state, self.jobs, config.checkpoint)
        self.actions.listeners.append(self._on_change)
        self.panels = [CapturePanel(self), ReconstructPanel(self), ViewportPanel(self), LightingPanel(self),
                       GuidancePanel(self), ExportPanel(self), LogPanel(self)]
        self.viewport = None
        self.ctx = None
        from .field_preview import FieldPreview
        from .panels.file_menu import FileMenu

        self.field_preview = FieldPreview()
        self.file_menu = FileMenu(self)
        self.user_environments: list[str] = list(config.extra_environments)
        self.capture_cameras, self.suggested_cameras = [], []
        self.world_from_capture: np.ndarray | None = None
        self.capture_scale = 1.0
        self._textures: dict = {}  # key -> (file mtime, texture)
        self._overlay_scales: dict = {}  # mask overlay key -> scale from the full image to its texture
        self._exit_asked = False
        self.exit_dialog_open = False
        self.script = None
        self.started = time.perf_counter()
        self.first_frame_seconds: float | None = None
        self.widget_rects: dict[str, list[float]] = {}  # named buttons' screen rectangles (scripted clicks)
        self._panel_errors: set[tuple[str, str]] = set()  # failures already reported
        self._good_frames = 0  # frames drawn since a capture was opened

    def guarded(self, panel):
        """The panel's draw function, made so that a failure in it is reported in Messages (once) instead of
        closing the window. A failure while the choices restored from the capture are in force drops them
        (they are what the window could not show): reopening a capture must never take the window down."""
        from imgui_bundle import imgui

        def draw() -> None:
            saved = imgui.internal.ErrorRecoveryState()
            imgui.internal.error_recovery_store_state(saved)
            try:
                panel.draw()
            except Exception as err:
                io = imgui.get_io()
                names = ("config_error_recovery_enable_assert", "config_error_recovery_enable_debug_log",
                         "config_error_recovery_enable_tooltip")
                before = [getattr(io, n) for n in names]
                for n in names:
                    setattr(io, n, False)
                try:  # close what the panel left open (tables, disabled blocks...), quietly: it is reported below
                    imgui.internal.error_recovery_try_to_recover_window_state(saved)
                finally:
                    for n, value in zip(names, before):
                        setattr(io, n, value)
                self._panel_failed(panel.title, err)
        return draw

    def _panel_failed(self, title: str, err: Exception) -> None:
        what = f"{type(err).__name__}: {err}"
        if self.state.choices_restored:
            log.exception("the %s panel failed with the restored state", title)
            try:
                self.actions.drop_restored_choices(f"the {title} panel failed: {what}")
                return
            except Exception:  # not the saved state's doing after all: reported as any other failure
                log.exception("dropping the restored state did not help")
        if (title, what) not in self._panel_errors:
            self._panel_errors.add((title, what))
            log.exception("the %s panel failed", title)
            self.state.say(f"the {title} panel failed: {what} (the window goes on; the log has the details)", "error")

    def note_widget(self, name: str) -> None:
        """Remember where the last drawn item is, in window pixels: [x0, y0, x1, y1]."""
        from imgui_bundle import imgui

        a, b = imgui.get_item_rect_min(), imgui.get_item_rect_max()
        self.widget_rects[name] = [a.x, a.y, b.x, b.y]

    # ---- runner callbacks ----------------------------------------------------------------------
    def post_init(self) -> None:
        import moderngl

        from .viewport import Viewport

        self.ctx = moderngl.create_context()
        self.viewport = Viewport(self.ctx)
        self._apply_environment()
        if self.config.capture is not None:
            self.actions.open_capture(self.config.capture)
        elif self.config.demo:
            self.actions.open_demo_capture(reconstruct=True)
        elif self.config.reopen_last:
            from .recent import last_capture

            last = last_capture()
            if last is not None:
                self.actions.open_capture(last)
        if self.config.script is not None:
            from .script import ScriptRunner

            self.script = ScriptRunner(self, self.config.script)

    def pre_new_frame(self) -> None:
        self.jobs.poll()
        if self.script is not None:
            self.script.step()
        self._set_idling()

    def _set_idling(self) -> None:
        """Draw only when something changes: an idle window (no input, no job, no field being rendered)
        sleeps until the next input event or IDLE_FPS times a second at most; while work is under way it
        redraws at WORKING_FPS so that its progress shows."""
        from imgui_bundle import hello_imgui

        working = bool(self.jobs.running()) or self.field_preview.busy() or self.script is not None
        idling = hello_imgui.get_runner_params().fps_idling
        idling.fps_idle = WORKING_FPS if working else IDLE_FPS

    def after_frame(self) -> None:
        if self.first_frame_seconds is None:
            self.first_frame_seconds = time.perf_counter() - self.started
            log.info("first frame after %.2f s", self.first_frame_seconds)
        self._good_frames += 1
        if self._good_frames > 10:
            self.state.choices_restored = False  # the restored choices are shown: from now on they are the user's
        if self.script is not None:
            self.script.after_frame()

    def before_swap(self) -> None:
        if self.script is not None:
            self.script.before_swap()

    def confirm_exit(self) -> bool:
        """Closing with work under way: ask (in the window) instead of dropping it."""
        if self.jobs.running():
            self._exit_asked = True
            return False
        return True

    def before_exit(self) -> None:
        self.field_preview.close()  # a field render still running would abort the interpreter's exit
        left = self.jobs.shutdown()
        for job in left:
            log.warning("%s goes on in the background (process %d); its file arrives when it is done", job.title, job.process.pid)
        self.state.save_choices()
        for cached in self._textures.values():
            cached[1].release()
        if self.viewport is not None:
            self.viewport.release()

    def show_menus(self) -> None:
        self.file_menu.draw_menu()

    def show_gui(self) -> None:
        from imgui_bundle import hello_imgui, imgui

        io = imgui.get_io()
        if io.key_ctrl and imgui.is_key_pressed(imgui.Key.n, False):
            self.file_menu.ask("new")
        elif io.key_ctrl and imgui.is_key_pressed(imgui.Key.o, False):
            self.file_menu.ask("open")
        self.file_menu.draw_dialogs()

        if self._exit_asked:
            imgui.open_popup("Work under way")
            self._exit_asked = False
        self.exit_dialog_open = imgui.is_popup_open("Work under way")
        if imgui.begin_popup_modal("Work under way", None, imgui.WindowFlags_.always_auto_resize)[0]:
            running = self.jobs.running()
            for job in running:
                imgui.text(f"{job.title}: {job.stage}")
            if running:
                imgui.text("Exports finish in the background if you quit now; other work is cancelled.")
            else:  # it ended while the question was up
                imgui.text("The work has finished: nothing is lost if you quit now.")
            if imgui.button("Keep working"):
                imgui.close_current_popup()
            imgui.same_line()
            if imgui.button("Quit"):
                imgui.close_current_popup()
                hello_imgui.get_runner_params().app_shall_exit = True
            imgui.end_popup()

    # ---- reacting to the action layer ----------------------------------------------------------
    def _on_change(self, event: str) -> None:
        if self.viewport is None:
            return
        if event == "capture":
            self._good_frames = 0
            self._load_capture_geometry()
        if event in ("asset", "capture", "guidance"):
            self._load_asset()
        if event == "guidance":
            self._load_suggested_cameras()
        if event in ("environment", "capture"):  # a reopened capture lights the viewport as it was left
            self._apply_environment()
        self.viewport.dirty = True

    def _load_capture_geometry(self) -> None:
        from lirm.engine.capture.capture_folder import Capture
        from lirm.engine.export.capture_export import export_transform

        capture = Capture.open(self.state.capture_dir)
        self.capture_cameras = [capture.cameras[f] for f in sorted(capture.cameras)]
        self.world_from_capture = export_transform(capture)
        self.capture_scale = 1.0
        self._load_suggested_cameras()

    def _load_suggested_cameras(self) -> None:
        from lirm.engine.cameras import Camera

        self.suggested_cameras = [Camera.from_dict(s["camera"]) for s in (self.state.guidance or {}).get("suggestions", [])]

    def _load_asset(self) -> None:
        view = self.state.choices.view
        if view.show_coverage and self.state.coverage is not None and self.world_from_capture is not None:
            self.viewport.set_asset(None, meshes=[self._coverage_mesh()], frame=self.viewport.scene is None)
            return
        path = self.state.preview_asset
        stamp = path.stat().st_mtime_ns if path is not None and path.is_file() else None
        if path == self.viewport.asset_path and stamp == self.viewport.asset_stamp and self.viewport.scene is not None:
            return
        from lirm.engine.export.glb_placement import read_units

        units = read_units(path) if path is not None else None
        reframe = self.viewport.scene is None or units != getattr(self, "_asset_units", units)  # e.g. now in metres
        self._asset_units = units
        try:
            self.viewport.set_asset(path, frame=reframe)
        except Exception as err:  # a damaged preview must not take the window down
            self.state.say(f"cannot show {path}: {err}", "error")
            return
        from lirm.engine.export.glb_placement import read_placement

        placement = read_placement(path) if path is not None else None
        if placement is not None and self.state.capture_dir is not None:
            # The export stands each asset on the ground by its own extent: cameras, coverage and the
            # field are drawn with the same placement as the mesh.
            self.world_from_capture = placement

    def _coverage_mesh(self):
        """The guidance surface coloured by how many cameras see each vertex well: red none, green 3+."""
        from lirm.renderer.material import PBRMaterial
        from lirm.renderer.mesh import MeshData

        data = self.state.coverage
        v = (np.c_[data["vertices"], np.ones(len(data["vertices"]))] @ self.world_from_capture.T)[:, :3]
        seen = np.clip(data["cameras_seeing"] / 3.0, 0.0, 1.0)
        colours = np.c_[1.0 - seen, seen, np.zeros_like(seen) + 0.1, np.ones_like(seen)].astype(np.float32) ** 2.2
        material = PBRMaterial(base_color_factor=(1, 1, 1, 1), metallic_factor=0.0, roughness_factor=0.8, double_sided=True)
        return MeshData(v.astype(np.float32), data["faces"].astype(np.uint32), colors=colours, material=material, name="coverage")

    def _apply_environment(self) -> None:
        from lirm.engine.assets.environment_files import resolve_environment

        from .app_state import BUILTIN_ENVIRONMENTS

        view = self.state.choices.view
        if view.environment == self.viewport.environment_key:
            return
        try:
            environment = resolve_environment(view.environment, width=self.config.environment_width)
        except Exception as err:
            self.state.say(f"cannot load the environment {view.environment}: {err}; back to the studio", "error")
            view.environment = "studio"
            environment = resolve_environment("studio", width=self.config.environment_width)
        if view.environment not in BUILTIN_ENVIRONMENTS and view.environment not in self.user_environments:
            self.user_environments.append(view.environment)  # an HDRI chosen in an earlier session: listed again
        from lirm.engine.lighting.camera_response import TONE_CURVE_OF_RESPONSE
        from lirm.engine.lighting.capture_lighting import camera_response_of

        self.viewport.set_environment(environment, view.environment, TONE_CURVE_OF_RESPONSE[camera_response_of(view.environment)])

    def add_environment(self, path: str) -> None:
        p = Path(path).expanduser().resolve()
        if not p.is_file() or p.suffix.lower() not in (".hdr", ".exr"):
            self.state.say(f"{path}: not an .hdr or .exr file", "error")
            return
        if str(p) not in self.user_environments:
            self.user_environments.append(str(p))
        self.actions.set_environment(str(p))

    def _cached_texture(self, key, stamp: float, make_rgba):
        """A texture made by make_rgba() -> (H, W, 4) uint8, remade only when `stamp` changes (a file's
        mtime), the old one released. None when make_rgba() has nothing to show."""
        cached = self._textures.get(key)
        if cached is not None and cached[0] == stamp:
            return cached[1]
        rgba = make_rgba()
        if rgba is None:
            return None
        texture = self.ctx.texture((rgba.shape[1], rgba.shape[0]), 4, np.ascontiguousarray(rgba).tobytes())
        if cached is not None:
            cached[1].release()
        self._textures[key] = (stamp, texture)
        return texture

    def picture_texture(self, path: Path):
        """A PNG on disk as a texture, cached until the file changes."""
        import cv2

        path = Path(path)
        if not path.is_file():
            return None

        def make():
            image = cv2.imread(str(path), cv2.IMREAD_COLOR)
            if image is None:
                return None
            return np.dstack([cv2.cvtColor(image, cv2.COLOR_BGR2RGB), np.full(image.shape[:2], 255, np.uint8)])
        return self._cached_texture(("picture", str(path)), path.stat().st_mtime, make)

    def thumbnail_texture(self, frame_id: str, size: int = 48):
        """The view's network crop (masked image) as a small texture, cached until the crop changes."""
        import cv2

        path = self.state.capture_dir / "prepared" / f"{frame_id}.npz"
        if not path.is_file():
            return None

        def make():
            try:
                with np.load(path) as data:
                    image = data["image_masked"]
            except (OSError, KeyError, ValueError):
                return None
            small = cv2.resize(np.asarray(image, np.float32), (size, size), interpolation=cv2.INTER_AREA)
            return np.dstack([(np.clip(small, 0, 1) * 255).astype(np.uint8), np.full((size, size), 255, np.uint8)])
        return self._cached_texture(("thumb", str(path)), path.stat().st_mtime, make)

    def mask_overlay_texture(self, frame_id: str, longest: int = 512):
        """A view's working image with its mask tinted, as (texture, scale from full image to texture);
        cached until the mask file changes (the capture is read only then, not every frame)."""
        import cv2

        from lirm.engine.capture.capture_folder import Capture

        mask_path = self.state.capture_dir / "masks" / f"{frame_id}.png"  # Capture.mask_path's layout
        stamp = mask_path.stat().st_mtime if mask_path.is_file() else 0.0
        key = ("mask", str(self.state.capture_dir), frame_id)

        def make():
            capture = Capture.open(self.state.capture_dir)
            try:
                image = capture.read_image(frame_id)[..., :3]
            except Exception as err:
                self.state.say(str(err), "error")
                return None
            s = min(1.0, longest / max(image.shape[:2]))
            small = cv2.resize(image, (round(image.shape[1] * s), round(image.shape[0] * s)), interpolation=cv2.INTER_AREA)
            mask = capture.read_mask(frame_id)
            if mask is not None:
                inside = cv2.resize(mask, small.shape[1::-1], interpolation=cv2.INTER_NEAREST) > 127
                small = np.where(inside[..., None], small, (small * 0.35).astype(np.uint8))  # outside the mask: dimmed
            self._overlay_scales[key] = s
            return np.dstack([small, np.full(small.shape[:2], 255, np.uint8)])
        texture = self._cached_texture(key, stamp, make)
        return None if texture is None else (texture, self._overlay_scales[key])


def runner_params(app: LirmApp):
    from imgui_bundle import hello_imgui, imgui

    params = hello_imgui.RunnerParams()
    params.app_window_params.window_title = "LIRM Studio"
    params.app_window_params.window_geometry.size = (app.config.width, app.config.height)
    params.imgui_window_params.default_imgui_window_type = hello_imgui.DefaultImGuiWindowType.provide_full_screen_dock_space
    params.imgui_window_params.show_status_bar = False
    params.imgui_window_params.show_menu_bar = True
    params.imgui_window_params.show_menu_app = False  # File is ours; the window's own close button quits
    params.imgui_window_params.show_menu_view = False
    # The layout is the code's and the user's choices live in the capture: no ini file. (An empty
    # ini_filename is not enough: HelloImGui then names one after the window title, in the cwd.)
    params.ini_disable = True
    params.fps_idling.fps_idle = IDLE_FPS  # see LirmApp._set_idling

    def split(new: str, direction, ratio: float, initial: str = "MainDockSpace"):
        s = hello_imgui.DockingSplit()
        s.initial_dock, s.new_dock, s.direction, s.ratio = initial, new, direction, ratio
        return s

    params.docking_params.docking_splits = [
        split("LeftSpace", imgui.Dir_.left, 0.27),
        split("RightSpace", imgui.Dir_.right, 0.27),
        split("BottomSpace", imgui.Dir_.down, 0.2),
        split("LeftBottom", imgui.Dir_.down, 0.45, "LeftSpace"),
        split("RightBottom", imgui.Dir_.down, 0.5, "RightSpace"),
    ]
    places = {"Capture": "LeftSpace", "Reconstruct": "LeftBottom", "Viewport": "MainDockSpace", "Lighting": "RightSpace",
              "Guidance": "RightBottom", "Export": "RightSpace", "Messages": "BottomSpace"}
    windows = []
    for panel in app.panels:
        w = hello_imgui.DockableWindow()
        w.label = panel.title
        w.dock_space_name = places[panel.title]
        w.gui_function = app.guarded(panel)
        windows.append(w)
    params.docking_params.dockable_windows = windows
    params.callbacks.post_init = app.post_init
    params.callbacks.pre_new_frame = app.pre_new_frame
    params.callbacks.show_gui = app.show_gui
    params.callbacks.show_menus = app.show_menus
    params.callbacks.after_swap = app.after_frame
    params.callbacks.before_swap = app.before_swap
    params.callbacks.confirm_exit = app.confirm_exit
    params.callbacks.before_exit = app.before_exit
    return params


def run_app(config: AppConfig = AppConfig()) -> LirmApp:
    from imgui_bundle import immapp

    app = LirmApp(config)
    immapp.run(runner_params(app))
    return app
