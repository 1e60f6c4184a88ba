"""The app's action layer: every user action as a method, used by the panels (buttons, menus) and by
the GUI tests and scripts alike, so what a test drives is what a click does.

Long actions start `lirm` jobs (jobs.py) and update the state when they finish; short ones change
the state at once. Nothing here draws.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.capture.ingest import SIDE_FILE_REASON
from lirm.engine.errors import LirmUserError

from .app_state import AppState, FrameInfo
from .jobs import Job, JobRunner

PREVIEW_FACES = 5000  # the viewport's asset after each update: small enough to export in seconds
PREVIEW_TEXTURE = 256
PREVIEW_GRID = 96
VIEWS_PER_UPDATE = 4  # when no views are picked, the next update takes the next unused ones
DEMO_CAPTURE_ENV = "LIRM_DEMO_CAPTURE"


class AppActions:
    def __init__(self, state: AppState, jobs: JobRunner, checkpoint: Path | None = None):
        self.state = state
        self.jobs = jobs
        self.checkpoint = checkpoint
        self.listeners: list = []  # callables(event: str) told about changes the viewport must follow
        self.cameras: dict = {}  # the open capture's posed cameras, by frame

    def _notify(self, event: str) -> None:
        for listener in self.listeners:
            listener(event)

    def _ckpt(self) -> list[str]:
        return ["--checkpoint", str(self.checkpoint)] if self.checkpoint else []

    # ---- the project ---------------------------------------------------------------------------
    def open_capture(self, path: str | Path) -> bool:
        path = Path(path).expanduser()
        try:
            capture = Capture.open(path)
        except (LirmUserError, OSError, ValueError) as err:
            self.state.say(f"cannot open {path}: {err}. Open a folder made by `lirm capture` or import photos.", "error")
            return False
        self.state.capture_dir = Path(capture.root).resolve()  # absolute: paths saved in it are made relative to it
        self.state.guidance, self.state.coverage, self.state.last_export = None, None, None
        self.state.load_choices()
        self._read_capture(capture)
        self._load_guidance()
        self.state.say(f"opened {self.state.capture_dir}: {len(capture.cameras)} posed views, {len(capture.updates)} updates")
        from .recent import remember_capture

        remember_capture(self.state.capture_dir)
        try:
            self._show_update(self.state.viewing_update)
            self._notify("capture")
        except Exception as err:
            if not self.state.choices_restored:
                raise
            # Whatever the saved state holds, opening does not fail on it: drop it and open as new.
            try:
                self.drop_restored_choices(f"{type(err).__name__}: {err}")
            except Exception as again:
                self.state.say(f"{self.state.capture_dir} is open but cannot be shown: {type(again).__name__}: {again}", "error")
        return True

    def drop_restored_choices(self, why: str) -> None:
        """The window's state saved in the capture cannot be shown: back to the default settings, said why
        (the file is rewritten at the next change)."""
        self.state.choices_restored = False
        self.state.say(f"the window's saved state in {self.state.capture_dir} could not be restored ({why}); "
                       "it was dropped and the capture opens with the default settings", "warning")
        from .app_state import SavedChoices

        self.state.choices = SavedChoices()
        self._show_update(self.state.viewing_update)
        self._notify("capture")

    def refresh(self) -> None:
        if self.state.capture_dir is not None:
            self._read_capture(Capture.open(self.state.capture_dir))

    def _read_capture(self, capture: Capture) -> None:
        used_in = {fid: u["update"] for u in capture.updates if u.get("kind", "update") == "update" for fid in u["frames"]}
        self.cameras = dict(capture.cameras)
        frames = []
        for fid in sorted(capture.frames):
            f = capture.frames[fid]
            frames.append(FrameInfo(fid, f.record.original.name, fid in capture.cameras, f.pose_status, f.mask_status,
                                    capture.prepared_path(fid).is_file(), used_in.get(fid)))
        self.state.frames = frames
        self.state.skipped_files = [(Path(r.path).name, r.reason) for r in capture.reports
                                    if not r.accepted and r.reason != SIDE_FILE_REASON]
        self.state.updates = list(capture.updates)
        self.state.weights = capture.updates[-1].get("weights", "") if capture.updates else ""
        self.state.real_size = capture.settings.get("real_size")
        known = {f.frame_id for f in frames if f.prepared}
        self.state.choices.selected = [f for f in self.state.choices.selected if f in known]

    def set_real_size(self, height_m: float) -> Job | None:
        """The object's real height: exports are in metres from then on (`lirm capture --real-size`)."""
        if self.state.capture_dir is None or not height_m > 0:
            self.state.say("give the object's height in centimetres (more than 0)", "warning")
            return None
        return self._start("capture", f"setting the height to {height_m:g} m",
                           ["capture", str(self.state.capture_dir), "--real-size", f"height={height_m:g}"],
                           lambda job: self._after_real_size(job))

    def _after_real_size(self, job: Job) -> None:
        self._after_capture_job(job, "setting the real size")
        if job.state == "finished" and self.state.viewing_update:
            self._show_update(self.state.viewing_update)  # the preview again, in metres

    def new_project(self, inputs: str | Path, new_capture: str | Path | None = None) -> Job | None:
        """File > New project from photos: a new capture from a folder of photos or a video (at
        `new_capture`, default a fresh folder beside the photos), opened when it is made, whatever
        capture is open now."""
        target = Path(new_capture) if new_capture else fresh_capture_folder(Path(inputs))
        return self.import_photos(inputs, target)

    def add_photos(self, inputs: str | Path) -> Job | None:
        """File > Add photos: more photos into the open capture (`lirm capture --add`)."""
        if self.state.capture_dir is None:
            self.state.say("no capture is open to add photos to: use File > New project from photos", "warning")
            return None
        return self.import_photos(inputs)

    def import_photos(self, inputs: str | Path, new_capture: str | Path | None = None) -> Job | None:
        """A folder of photos or a video: a new capture (at `new_capture`, default beside the photos),
        or added to the open one."""
        inputs = str(inputs)
        adding = self.state.capture_dir is not None and new_capture is None
        if adding:
            args = ["capture", inputs, str(self.state.capture_dir), "--add"]
            target = self.state.capture_dir
        else:
            target = Path(new_capture) if new_capture else fresh_capture_folder(Path(inputs))
            args = ["capture", inputs, "-o", str(target)]

        def done(job: Job) -> None:
            if job.state == "finished":
                nothing_new = adding and any("nothing new was added" in line for line in job.output)
                if nothing_new:
                    self.state.say(f"{inputs}: every photo is already in {target} (or was skipped): nothing new was added", "warning")
                before = set(self.state.skipped_files) if adding else set()
                self.open_capture(target)
                if not nothing_new:
                    self._say_skipped([s for s in self.state.skipped_files if s not in before], inputs)
                    self._say_exposure(target)
            elif job.state == "failed":
                self.state.say(f"importing {inputs} failed: {job.error_text()}", "error")
            else:
                self.state.say(f"importing {inputs} was cancelled; `lirm capture {target} --resume` finishes it")
        return self._start("capture", f"posing and masking {Path(inputs).name}", args, done)

    def _say_exposure(self, capture_dir: Path) -> None:
        """After an import: a warning when the photos' EXIF, or where it does not say, their shared
        backgrounds say the camera's exposure moved between them (exif_exposure.py,
        exposure_estimate.py), as the capture report says it."""
        from lirm.engine.capture.exif_exposure import exposure_note
        from lirm.engine.capture.exposure_match import estimated_exposure_note, white_balance_note

        capture = Capture.open(capture_dir)
        note = exposure_note([r.exposure_stops for r in capture.records])
        if note and note[1]:
            self.state.say(f"exposure: {note[0]}", "warning")
        estimated = estimated_exposure_note(capture)
        if estimated and estimated[1]:
            self.state.say(f"exposure, from the photos' backgrounds: {estimated[0]}", "warning")
        balance = white_balance_note(capture)
        if balance and balance[1]:  # said only where the photos were balanced for it
            self.state.say(f"white balance, from the photos' backgrounds: {balance[0]}")

    def _say_skipped(self, skipped: list[tuple[str, str]], inputs: str) -> None:
        """After an import: which files it did not take, and why (the Capture panel lists them all)."""
        if not skipped:
            return
        shown = "; ".join(f"{name}: {why}" for name, why in skipped[:2])
        more = f"; and {len(skipped) - 2} more" if len(skipped) > 2 else ""
        self.state.say(f"{len(skipped)} file{'s' if len(skipped) > 1 else ''} of {Path(inputs).name} not imported: "
                       f"{shown}{more} (listed in Capture)", "warning")

    def open_demo_capture(self, folder: str | Path | None = None, reconstruct: bool = False) -> Job | None:
        """The built-in demo capture (the mug of `lirm demo`), made once and reused; with `reconstruct`,
        updates run as views remain (what `make demo` shows)."""
        import os

        folder = Path(folder or os.environ.get(DEMO_CAPTURE_ENV) or Path.home() / ".cache" / "lirm" / "demo")
        capture = folder / "capture"

        def opened() -> None:
            if self.open_capture(capture) and reconstruct and not self.state.updates:
                self.state.choices.auto_update = True
                self.run_update()

        if (capture / "capture.json").is_file() and Capture.open(capture).cameras:
            opened()
            return None

        def done(job: Job) -> None:
            if job.state == "finished":
                opened()
            else:
                self.state.say(f"making the demo capture failed: {job.error_text()}", "error")
        return self._start("capture", "making the demo capture (photos of a mug, posed by COLMAP)",
                           ["demo", "-o", str(folder), "--capture-only"], done)

    # ---- views ---------------------------------------------------------------------------------
    def select_views(self, frame_ids: list[str]) -> None:
        known = {f.frame_id for f in self.state.frames if f.prepared}
        self.state.choices.selected = [f for f in frame_ids if f in known]
        self.state.save_choices()

    def toggle_view(self, frame_id: str) -> None:
        chosen = self.state.choices.selected
        self.select_views([f for f in chosen if f != frame_id] if frame_id in chosen else chosen + [frame_id])

    def next_views(self) -> list[str]:
        """The views the next update will take: the picked ones, else the next unused ones."""
        if self.state.choices.selected:
            return list(self.state.choices.selected)
        from lirm.engine.reconstruction.session import spread_order

        # Refinements fit every view; only the updates' views are used up.
        used = [f for u in self.state.updates[:self.state.viewing_update] if u.get("kind", "update") == "update" for f in u["frames"]]
        free = [f.frame_id for f in self.state.frames if f.prepared and f.frame_id not in set(used)]
        if self.cameras and all(f in self.cameras for f in free + used):
            free = spread_order(free, self.cameras, used)  # spread over the object, as `lirm reconstruct` splits them
        return free[:VIEWS_PER_UPDATE]

    def fix_mask_with_box(self, frame_id: str, box: tuple[int, int, int, int]) -> Job | None:
        """The object is inside this box (x0, y0, x1, y1, full-image pixels) of one view: GrabCut there
        gives the corrected mask, which `lirm capture --fix-mask` propagates to the other views."""
        import cv2

        capture = Capture.open(self.state.capture_dir)
        image = capture.read_image(frame_id)
        x0, y0, x1, y1 = (int(v) for v in box)
        h, w = image.shape[:2]
        x0, x1 = sorted((max(0, min(w - 1, x0)), max(0, min(w, x1))))
        y0, y1 = sorted((max(0, min(h - 1, y0)), max(0, min(h, y1))))
        if x1 - x0 < 8 or y1 - y0 < 8:
            self.state.say("draw a larger box round the object", "warning")
            return None
        bgr = cv2.cvtColor(np.asarray(image[..., :3] * 255 if image.dtype != np.uint8 else image[..., :3], np.uint8), cv2.COLOR_RGB2BGR)
        mask = np.zeros((h, w), np.uint8)
        bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
        cv2.grabCut(bgr, mask, (x0, y0, x1 - x0, y1 - y0), bgd, fgd, 4, cv2.GC_INIT_WITH_RECT)
        fixed = np.where((mask == cv2.GC_FGD) | (mask == cv2.GC_PR_FGD), 255, 0).astype(np.uint8)
        path = self.state.capture_dir / "app" / f"fixed_mask_{frame_id}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(path), fixed)
        return self._start("capture", f"fixing the mask of {frame_id}",
                           ["capture", str(path), str(self.state.capture_dir), "--fix-mask", frame_id],
                           lambda job: self._after_capture_job(job, "fixing the mask"))

    def _after_capture_job(self, job: Job, what: str) -> None:
        if job.state == "failed":
            self.state.say(f"{what} failed: {job.error_text()}", "error")
        self.refresh()

    # ---- reconstruction ------------------------------------------------------------------------
    def run_update(self) -> Job | None:
        if self.state.capture_dir is None:
            self.state.say("open or import a capture first", "warning")
            return None
        if self.jobs.running("update") or self.jobs.running("refine"):
            self.state.say("an update or refinement is already running", "warning")
            return None
        frames = self.next_views()
        if not frames:
            self.state.say("every view is used: import more photos (or step back) for another update", "warning")
            return None
        after = self.state.viewing_update
        number = after + 1
        args = ["reconstruct", str(self.state.capture_dir), "--frames", ",".join(frames), "--after", str(after),
                "--novel-views", "1", "--render-size", "64", "--grid-resolution", "64", *self._ckpt()]

        def done(job: Job) -> None:
            if job.state == "finished":
                self.state.choices.selected = []
                self.state.choices.viewing_update = None
                self.refresh()
                self.state.save_choices()
                memory = f", peak memory {job.peak_memory_mb:.0f} MB" if job.peak_memory_mb else ""
                self.state.update_costs[number] = (job.seconds, job.peak_memory_mb)
                self.state.say(f"update {number}: {len(frames)} views in {job.seconds:.1f} s{memory}")
                self._show_update(number)
                if self.state.choices.auto_update and self.next_views():
                    self.run_update()
            elif job.state == "failed":
                self.state.say(f"update {number} failed: {job.error_text()}", "error")
            else:
                self.state.say(f"update {number} cancelled; the reconstruction is as it was")
        return self._start("update", f"LIRM update {number} ({len(frames)} views)", args, done)

    def live_refine_path(self) -> Path | None:
        """The field as the running refinement has it (refreshed every few seconds), or None."""
        if self.state.capture_dir is None or not self.jobs.running("refine"):
            return None
        path = self.state.capture_dir / "app" / "refine_live.safetensors"
        return path if path.is_file() else None

    def refine_arguments(self, minutes: float, live: Path) -> list[str]:
        """The `lirm refine` command line the Refine button runs, with the panel's choices."""
        args = ["refine", str(self.state.capture_dir), "--minutes", f"{minutes:g}", "--novel-views", "1", "--render-size", "64",
                "--grid-resolution", "64", "--live", str(live), "--live-every", "4", *self._ckpt()]
        if self.state.choices.refine_materials:
            args.append("--materials")
            if not self.state.choices.refine_material_network:
                args += ["--material-network", "off"]
        if not self.state.choices.refine_carve_openings:
            args.append("--no-carve-openings")
        return args

    def run_refine(self, minutes: float | None = None) -> Job | None:
        """Per-scene refinement of the latest step on all the views (`lirm refine`), shown live in the
        viewport's field channel; Cancel keeps the best state so far as a step of the history."""
        if self.state.capture_dir is None:
            self.state.say("open or import a capture first", "warning")
            return None
        if self.jobs.running("refine") or self.jobs.running("update"):
            self.state.say("wait for the running update or refinement to finish", "warning")
            return None
        if self.state.viewing_update != len(self.state.updates):
            self.state.say("refinement goes on from the latest step: step forward to it (or run an update) first", "warning")
            return None
        minutes = float(minutes or self.state.choices.refine_minutes)
        number = len(self.state.updates) + 1
        live = self.state.capture_dir / "app" / "refine_live.safetensors"
        live.parent.mkdir(parents=True, exist_ok=True)
        args = self.refine_arguments(minutes, live)
        previous_channel = self.state.choices.view.channel
        self.set_channel("field")  # the field as it fits; the mesh preview follows when it is done

        def done(job: Job) -> None:
            self.refresh()
            kept = len(self.state.updates) >= number
            if kept:
                self.state.choices.viewing_update = None
                self.state.save_choices()
                self.state.update_costs[number] = (job.seconds, job.peak_memory_mb)
                how = "stopped early; the best state so far is" if job.state == "cancelled" else "done;"
                self.state.say(f"refinement {how} step {number} of the history ({job.seconds:.0f} s)")
                self._show_update(number)
            elif job.state == "failed":
                self.state.say(f"refinement failed: {job.error_text()}", "error")
            elif job.returncode is not None and job.returncode < 0:
                self.state.say(f"refinement did not stop within {job.cancel_grace:.0f} s of Cancel and was killed; "
                               f"the reconstruction is as it was", "warning")
            else:
                self.state.say("refinement cancelled before it could keep anything; the reconstruction is as it was")
            if self.state.choices.view.channel == "field":
                self.set_channel(previous_channel)
        # A cancelled refinement still saves its best state, renders its preview and writes the history;
        # on a loaded machine that can take a while, and killing it then would lose the work.
        return self._start("refine", f"refinement {number} ({minutes:g} min)", args, done, cancel_grace=180.0)

    def step_back(self, update: int) -> None:
        """Look at (and go on from) an earlier update; later ones stay until a new update replaces them."""
        self.state.choices.viewing_update = max(0, min(update, len(self.state.updates)))
        self.state.save_choices()
        self._show_update(self.state.viewing_update)

    def _show_update(self, update: int) -> None:
        if update < 1 or self.state.capture_dir is None:
            self.state.preview_asset = None
            self._notify("asset")
            return
        from lirm.engine.export.glb_placement import read_units

        path = self.preview_path(update)
        units = "metres" if self.state.real_size else "capture units"
        if (path.is_file() and read_units(path) == units
                and path.stat().st_mtime >= (self.state.capture_dir / self.state.updates[update - 1]["state"]).stat().st_mtime):
            self.state.preview_asset = path
            self._notify("asset")
            return

        path.parent.mkdir(parents=True, exist_ok=True)

        def done(job: Job) -> None:
            if job.state == "finished" and self.state.viewing_update == update:
                self.state.preview_asset = path
                self._notify("asset")
            elif job.state == "failed":
                self.state.say(f"the preview of update {update} failed: {job.error_text()}", "error")
        self._start("preview", f"preview of update {update}",
                    ["export", str(self.state.capture_dir), "-o", str(path), "--update", str(update), "--faces", str(PREVIEW_FACES),
                     "--texture", str(PREVIEW_TEXTURE), "--grid", str(PREVIEW_GRID), "--no-normal-map", *self._ckpt()], done)

    def preview_path(self, update: int) -> Path:
        return self.state.capture_dir / "app" / "preview" / f"update_{update:02d}.glb"

    # ---- guidance ------------------------------------------------------------------------------
    def ask_guidance(self, k: int = 4) -> Job | None:
        if self.state.capture_dir is None:
            self.state.say("open or import a capture first", "warning")
            return None

        def done(job: Job) -> None:
            if job.state == "finished":
                self._load_guidance()
                g = self.state.guidance or {}
                self.state.say(f"guidance: covered {100 * g.get('coverage_now', 0):.0f}% now, "
                               f"{100 * g.get('coverage_after', 0):.0f}% after {len(g.get('suggestions', []))} more shots")
                self._notify("guidance")
            elif job.state == "failed":
                self.state.say(f"guidance failed: {job.error_text()}", "error")
        return self._start("suggest", "next-view guidance", ["suggest", str(self.state.capture_dir), "--k", str(k), *self._ckpt()], done)

    def _load_guidance(self) -> None:
        folder = self.state.capture_dir / "guidance"
        try:
            self.state.guidance = json.loads((folder / "suggestions.json").read_text()) if (folder / "suggestions.json").is_file() else None
            if (folder / "surface_coverage.npz").is_file():
                with np.load(folder / "surface_coverage.npz") as data:
                    self.state.coverage = {k: data[k] for k in data.files}
        except (ValueError, OSError) as err:
            self.state.say(f"the guidance files in {folder} are damaged ({err}); ask for guidance again", "warning")

    # ---- viewport and lighting -----------------------------------------------------------------
    def set_channel(self, channel: str) -> None:
        self.state.choices.view.channel = channel
        self._changed_view()

    def set_environment(self, name_or_path: str) -> None:
        from .app_state import BUILTIN_ENVIRONMENTS

        name = str(name_or_path)
        self.state.choices.view.environment = name if name in BUILTIN_ENVIRONMENTS else str(Path(name).expanduser().resolve())
        self._changed_view("environment")

    def set_rotation(self, degrees: float) -> None:
        self.state.choices.view.rotation_deg = float(degrees) % 360.0
        self._changed_view()  # applied when drawing: no new environment to prepare

    def set_exposure(self, ev: float) -> None:
        self.state.choices.view.exposure_ev = float(ev)
        self._changed_view()

    def set_background(self, on: bool) -> None:
        self.state.choices.view.background = bool(on)
        self._changed_view()

    def set_show_cameras(self, on: bool) -> None:
        self.state.choices.view.show_cameras = bool(on)
        self._changed_view()

    def set_show_guides(self, on: bool) -> None:
        self.state.choices.view.show_guides = bool(on)
        self._changed_view()

    def set_show_coverage(self, on: bool) -> None:
        self.state.choices.view.show_coverage = bool(on)
        self._changed_view("asset")

    def _changed_view(self, event: str = "view") -> None:
        self.state.save_choices()
        self._notify(event)

    # ---- export --------------------------------------------------------------------------------
    def export(self, path: str | Path | None = None, faces: int | None = None, texture: int | None = None,
               grid: int | None = None) -> Job | None:
        if not self.state.updates:
            self.state.say("nothing to export yet: run an update first", "warning")
            return None
        settings = self.state.choices.export
        settings.faces = faces or settings.faces
        settings.texture = texture or settings.texture
        settings.grid = grid or settings.grid
        out = self.state.capture_path(path or settings.path or self.default_export_path())  # relative: in the capture
        settings.path = str(out)
        try:
            out.parent.mkdir(parents=True, exist_ok=True)  # the user named it in the panel: make its folder
        except OSError as err:
            self.state.say(f"cannot export to {out}: {err}; choose another folder", "error")
            return None
        self.state.save_choices()
        args = ["export", str(self.state.capture_dir), "-o", str(out), "--faces", str(settings.faces), "--texture",
                str(settings.texture), "--grid", str(settings.grid), "--update", str(max(1, self.state.viewing_update)), *self._ckpt(),
                *([] if settings.fit_textures else ["--no-texture-fit"])]

        def done(job: Job) -> None:
            if job.state == "finished":
                self.state.last_export = out
                self.state.say(f"exported {out} in {job.seconds:.0f} s")
            elif job.state == "failed":
                self.state.say(f"export failed: {job.error_text()}", "error")
            else:
                self.state.say("export cancelled; any earlier file there is untouched")
        return self._start("export", f"exporting {out.name}", args, done, detach_on_exit=True)

    def default_export_path(self) -> Path:
        return self.state.capture_dir / "export" / "asset.glb"

    def export_turntable(self, folder: str | Path | None = None) -> Job | None:
        """An image sequence orbiting the last exported asset under the current lighting."""
        if self.state.capture_dir is None:
            self.state.say("open or import a capture first", "warning")
            return None
        asset = self.state.last_export or self.state.capture_path(self.state.choices.export.path or self.default_export_path())
        if not asset.is_file():
            self.state.say(f"export the asset first; the turntable shows the exported file ({asset} is not there yet)", "warning")
            return None
        out = self.state.capture_path(folder) if folder else asset.with_name(asset.stem + "_turntable")
        view = self.state.choices.view
        args = ["render", str(asset), "--env", view.environment, "--views", str(self.state.choices.export.turntable_frames),
                "--size", "512x512", "-o", str(out)]

        def done(job: Job) -> None:
            level = "info" if job.state == "finished" else "error"
            self.state.say(f"turntable in {out}" if job.state == "finished" else f"turntable failed: {job.error_text()}", level)
        return self._start("render", "turntable", args, done, detach_on_exit=True)

    # ---- jobs ----------------------------------------------------------------------------------
    def _start(self, kind: str, title: str, args: list[str], done, detach_on_exit: bool = False,
               cancel_grace: float | None = None) -> Job | None:
        try:
            if cancel_grace is None:
                return self.jobs.start(kind, title, args, done, detach_on_exit)
            return self.jobs.start(kind, title, args, done, detach_on_exit, cancel_grace)
        except OSError as err:
            self.state.say(f"could not start {title}: {err}", "error")
            return None

    def cancel(self, kind: str) -> None:
        for job in self.jobs.running(kind):
            self.jobs.cancel(job)


def fresh_capture_folder(inputs: Path) -> Path:
    """PHOTOS_capture beside the photos, or PHOTOS_capture_2, _3, ... when that is taken."""
    base = inputs.with_name(inputs.stem + "_capture")
    candidate, k = base, 2
    while candidate.exists():
        candidate, k = base.with_name(f"{base.name}_{k}"), k + 1
    return candidate
