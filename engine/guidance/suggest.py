"""`lirm suggest CAPTURE`: where to shoot next, for a capture as it stands.

The surface is the latest reconstruction's mesh (marching cubes at a coarse grid), weighted by the
model's uncertainty (uncertainty.py: change over the last two updates, view dependence, low
opacity), or, before any reconstruction, the object's bounding sphere (the capture is normalised so
that the object fits the unit sphere), with a message saying so. Cameras are the capture's posed views in its normalised frame.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import trimesh

from lirm.engine.capture.capture_folder import Capture
from lirm.engine.errors import LirmUserError
from lirm.engine.io.images import write_png

from .coverage import SurfaceCoverage
from .next_views import CandidateConfig, Suggestion, camera_angles, suggest_next_views


@dataclass
class CaptureSuggestions:
    suggestions: list[Suggestion]
    heat_map: np.ndarray  # (elevations, azimuths) gain of each candidate
    coverage_before: float  # share of the surface covered now
    coverage_after: float  # ... once the suggestions are shot
    vertex_coverage: np.ndarray  # (V,) cameras seeing each vertex well
    surface: str  # where the surface came from
    notes: list[str]
    vertices: np.ndarray  # (V, 3) the surface, in the capture's normalised frame
    faces: np.ndarray  # (F, 3)
    uncertainty: np.ndarray | None  # (V,) the model's uncertainty in [0, 1], None before a reconstruction
    candidates: CandidateConfig = field(default_factory=CandidateConfig)  # the heat map's rows and columns
    photo_distance: float = 2.5  # the photos' median distance from the object's centre (normalised units)


BOUNDING_SPHERE_RADIUS = 0.8  # the normalised object fits the unit sphere with some room


def bounding_sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(3, radius=BOUNDING_SPHERE_RADIUS)


def field_surface(field, resolution: int, face_budget: int = 5000) -> tuple[trimesh.Trimesh, str | None]:
    """The field's mesh to cover, or the bounding sphere and why, when the field has no surface yet."""
    from lirm.engine.export.field_mesh import MeshExtractionConfig, NoSurfaceError, extract_field_mesh

    try:
        return extract_field_mesh(field, MeshExtractionConfig(resolution=resolution, face_budget=face_budget)), None
    except NoSurfaceError as err:
        return bounding_sphere(), str(err)


def _surface(capture: Capture, checkpoint, grid: int) -> tuple[trimesh.Trimesh, str, list[str], list]:
    """The surface to cover, where it came from, notes for the user, and the last two updates' fields."""
    notes = []
    if capture.updates:
        from lirm.engine.export.capture_export import latest_state_path, reconstruction_model
        from lirm.engine.model.field_state import load_field

        model = reconstruction_model(capture, checkpoint).model
        latest = load_field(latest_state_path(capture), model)  # an update's state or a refined one
        previous_state = capture.root / capture.updates[-2]["state"] if len(capture.updates) > 1 else None
        fields = ([load_field(previous_state, model)] if previous_state and previous_state.is_file() else []) + [latest]
        mesh, why_not = field_surface(latest, grid)
        if why_not is None:
            kind = "refinement" if capture.updates[-1].get("kind") == "refine" else "update"
            return mesh, f"reconstruction after {kind} {len(capture.updates)}", notes, fields
        notes.append(f"the reconstruction has no surface yet ({why_not}); using the bounding sphere instead")
    else:
        notes.append("no reconstruction yet: suggestions come from how the cameras cover the object's bounding sphere")
    return bounding_sphere(), "bounding sphere", notes, []


OCCLUDER_FACES = 1500  # the surface that hides things, for the depth maps of 240 candidates


def occluding_coverage(renderer, mesh: trimesh.Trimesh, occluder_faces: int | None = OCCLUDER_FACES) -> SurfaceCoverage:
    """Coverage of the mesh's vertices, with a coarser copy of it drawn as the occluder: the depth pass
    costs in proportion to the faces drawn (0.27 s for 240 candidates at 5000 faces on this CPU), and
    the copy stays within a fraction of the 2% depth tolerance of the mesh."""
    occluder = mesh
    if occluder_faces and len(mesh.faces) > occluder_faces:
        from lirm.engine.export.field_mesh import decimate

        occluder = decimate(mesh, occluder_faces)
    return SurfaceCoverage(renderer, occluder.vertices, occluder.faces, None,
                           points=mesh.vertices, point_normals=mesh.vertex_normals)


def stands_on_something(capture: Capture, cameras: list) -> bool:
    """Whether the object rests on a floor or table: a support plane under it, or no photo ever taken
    from below its centre (a mug on a table cannot be shot from underneath unless it is turned over)."""
    plane = capture.normalization.plane if capture.normalization is not None else None
    if plane is not None and float(plane[0][2]) > 0.9:
        return True
    return bool(cameras) and min(camera_angles(c)[1] for c in cameras) > -5.0


def suggest_for_capture(renderer, capture_dir: str | Path, k: int = 4, checkpoint=None, grid: int = 64,
                        timings: dict[str, float] | None = None,
                        occluder_faces: int | None = OCCLUDER_FACES, can_turn: bool = False) -> CaptureSuggestions:
    """`timings`, when given, receives the seconds of each part (lirm bench suggest).
    `occluder_faces`: see occluding_coverage (None: the mesh itself). `can_turn`: the object can be
    turned over, so views from below it are reachable even when it stands on something."""
    clock = _Clock(timings)
    capture = Capture.open(capture_dir)
    cameras = [capture.cameras[f] for f in sorted(capture.cameras)]
    if not cameras:
        raise LirmUserError(f"{capture.root} has no posed views yet: run `lirm capture` on it first")
    mesh, surface, notes, fields = _surface(capture, checkpoint, grid)
    clock.lap("surface")
    weights, uncertainty = None, None
    if fields:
        from .uncertainty import guidance_weights, vertex_uncertainty

        uncertainty = vertex_uncertainty(fields, mesh.vertices, mesh.vertex_normals)["total"]
        weights = guidance_weights(uncertainty)
    clock.lap("uncertainty")
    if len(cameras) == 1:
        notes.append("only one view so far: every suggestion is about getting round the object")
    spread = np.ptp([c.center for c in cameras], axis=0).max() if len(cameras) > 1 else 0.0
    if len(cameras) > 1 and spread < 0.05:
        notes.append("all views were taken from about the same spot: walk round the object")
    config = CandidateConfig()
    if not can_turn and stands_on_something(capture, cameras):
        config = CandidateConfig(elevations_deg=tuple(e for e in config.elevations_deg if e >= 0.0))
        notes.append("the object stands on something (no photo from below it): suggestions stay above it; "
                     "pass --can-turn if it can be turned over")
    coverage = occluding_coverage(renderer, mesh, occluder_faces)
    try:
        looks = coverage.view_cosines(cameras)
        vertex_coverage = (looks > 0).sum(axis=0).astype(np.int32)
        clock.lap("coverage")
        suggestions, heat = suggest_next_views(coverage, cameras, k, weights=weights, config=config,
                                               quality_now=looks.max(axis=0))
        clock.lap("candidates")
    finally:
        coverage.release()
    before = float((vertex_coverage > 0).mean())
    # Each suggestion's new coverage counts what the ones before it left: together, what the shots add.
    return CaptureSuggestions(suggestions, heat, before, before + sum(s.new_coverage for s in suggestions),
                              vertex_coverage, surface, notes, np.asarray(mesh.vertices, np.float32),
                              np.asarray(mesh.faces, np.int32), uncertainty, config,
                              float(np.median([camera_angles(c)[2] for c in cameras])))


def write_guidance(folder: Path, result: CaptureSuggestions) -> dict[str, Path]:
    """What the app draws, beside the heat map: suggestions.json (ranked shots with their cameras) and
    surface_coverage.npz (the surface with per-vertex camera counts and uncertainty)."""
    from lirm.engine.io.atomic_files import atomic_write, atomic_write_json

    folder = Path(folder)
    suggestions = [{"rank": n, "azimuth_deg": s.azimuth_deg, "elevation_deg": s.elevation_deg, "distance": s.distance,
                    "look_at": list(s.look_at), "gain": s.gain, "new_coverage": s.new_coverage, "sentence": s.sentence,
                    "camera": s.camera.to_dict()}
                   for n, s in enumerate(result.suggestions, start=1)]
    config = result.candidates  # the rows the heat map has (no views from below an object that stands on something)
    json_path = atomic_write_json(folder / "suggestions.json", {
        "surface": result.surface, "coverage_now": result.coverage_before, "coverage_after": result.coverage_after,
        "notes": result.notes, "suggestions": suggestions,
        "heat_map": {"gain": np.round(result.heat_map, 5).tolist(), "elevations_deg": list(config.elevations_deg),
                     "azimuth_step_deg": config.azimuth_step_deg},
        "frame": "the capture's normalised frame (object in the unit sphere, +Z up); cameras as in transforms.json"})
    arrays = {"vertices": result.vertices, "faces": result.faces, "cameras_seeing": result.vertex_coverage.astype(np.int32)}
    if result.uncertainty is not None:
        arrays["uncertainty"] = result.uncertainty.astype(np.float32)

    def save(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)

    npz_path = atomic_write(folder / "surface_coverage.npz", save)
    return {"suggestions": json_path, "coverage": npz_path}


class _Clock:
    def __init__(self, timings: dict[str, float] | None):
        self.timings = timings
        self.last = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        if self.timings is not None:
            self.timings[name] = self.timings.get(name, 0.0) + now - self.last
        self.last = now


def write_heat_map(path: Path, heat: np.ndarray, suggestions: list[Suggestion], config: CandidateConfig = CandidateConfig()) -> Path:
    """Azimuth across, elevation up; brighter = more surface gained; suggestions numbered."""
    cell, left, top, bottom, legend_w = 24, 60, 24, 48, 110
    rows, cols = heat.shape
    peak = max(float(heat.max()), 1e-9)
    image = cv2.applyColorMap((heat[::-1] / peak * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)
    image = cv2.resize(image, (cols * cell, rows * cell), interpolation=cv2.INTER_NEAREST)
    height, width = top + rows * cell + bottom, left + cols * cell + legend_w
    pad = np.full((height, width, 3), 255, np.uint8)
    pad[top:top + rows * cell, left:left + cols * cell] = image

    def text(s: str, x: int, y: int, scale: float = 0.4, colour=(0, 0, 0), thickness: int = 1) -> None:
        cv2.putText(pad, s, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, thickness, cv2.LINE_AA)

    text("where to shoot next: surface each view would newly cover", left, 16, 0.45)
    for r, elevation in enumerate(config.elevations_deg[::-1]):
        text(f"{elevation:.0f}", left - 26, top + r * cell + 16)
    for c in range(0, cols, 3):
        text(f"{c * config.azimuth_step_deg:.0f}", left + c * cell, top + rows * cell + 16)
    text("azimuth (degrees, 0 = the first photo's side)", left, top + rows * cell + 38)
    label = np.full((14, rows * cell, 3), 255, np.uint8)  # the elevation axis title, written sideways
    cv2.putText(label, "elevation (degrees)", (4, 11), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    pad[top:top + rows * cell, 2:16] = np.rot90(label).copy()
    # Legend: the colour scale, from nothing new to the best candidate's share of the surface.
    x0 = left + cols * cell + 16
    ramp = cv2.applyColorMap(np.linspace(255, 0, rows * cell).astype(np.uint8)[:, None].repeat(16, axis=1), cv2.COLORMAP_INFERNO)
    pad[top:top + rows * cell, x0:x0 + 16] = ramp
    text("most", x0 + 20, top + 10)  # the gain weighs uncertain parts more: a relative scale
    text("none", x0 + 20, top + rows * cell)
    text("new", x0 + 20, top + rows * cell // 2 - 4)
    text("surface", x0 + 20, top + rows * cell // 2 + 10)
    for n, s in enumerate(suggestions, start=1):
        c = int(round(s.azimuth_deg / config.azimuth_step_deg)) % cols
        r = rows - 1 - list(config.elevations_deg).index(s.elevation_deg)
        text(str(n), left + c * cell + 7, top + r * cell + 17, 0.5, (80, 255, 80), 2)
    return write_png(path, pad[..., ::-1])
