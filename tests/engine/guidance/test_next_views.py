"""Next views: with only the front photographed, the first suggestions go round the back."""

import numpy as np
import pytest
import trimesh

from lirm.engine.cameras import orbit_camera
from lirm.engine.guidance.coverage import SurfaceCoverage
from lirm.engine.guidance.next_views import camera_angles, describe_move, greedy_views, suggest_next_views


def test_camera_angles_invert_orbit_camera():
    camera = orbit_camera(123.0, 35.0, 2.5, 64, 64, 50.0)
    azimuth, elevation, distance = camera_angles(camera)
    assert abs(azimuth - 123.0) < 1e-6 and abs(elevation - 35.0) < 1e-6 and abs(distance - 2.5) < 1e-9


def test_sentences_speak_the_photographers_language():
    assert describe_move(0, 20, 90, 20) == "Move 90° to your right"
    assert describe_move(90, 20, 45, 50) == "Move 45° to your left and raise the camera by 30° (look down on it)"
    assert describe_move(0, 20, 180, 20) == "Go round to the other side"
    assert describe_move(0, 20, 5, 25) == "Shoot again from about here"


def test_front_only_capture_gets_sent_round_the_back(renderer):
    mesh = trimesh.creation.icosphere(3, radius=0.6)
    mesh.vertices[:, 2] *= 0.8
    coverage = SurfaceCoverage(renderer, mesh.vertices, mesh.faces, mesh.vertex_normals)
    try:
        front = [orbit_camera(a, 20.0, 2.5, 96, 96, 50.0) for a in (-30.0, 0.0, 30.0)]
        before = (coverage.covered(front) > 0).mean()
        suggestions, heat = suggest_next_views(coverage, front, k=3)
        assert 0.2 < before < 0.7
        first = suggestions[0]
        assert abs((first.azimuth_deg - 180.0 + 180.0) % 360.0 - 180.0) <= 60.0, first
        assert heat.shape == (10, 24) and heat.max() == first.gain
        after = (coverage.covered(front + [s.camera for s in suggestions]) > 0).mean()
        assert after > before + 0.3
        # What each shot is said to add, in turn, adds up to what the shots add together.
        assert sum(s.new_coverage for s in suggestions) == pytest.approx(after - before)
        assert suggestions[0].new_coverage > 0.15
    finally:
        coverage.release()


def test_lirm_suggest_on_a_capture_with_and_without_a_reconstruction(lego_capture, tmp_path, capsys):
    import shutil

    import cv2

    from lirm.engine.cli import main

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["suggest", str(capture), "--k", "3"]) == 0
    captured = capsys.readouterr()
    assert "no reconstruction yet" in captured.err and "surface: bounding sphere" in captured.out
    assert "1. azimuth" in captured.out and "3. azimuth" in captured.out and "of the surface newly covered" in captured.out
    heat = cv2.imread(str(capture / "guidance" / "heat_map.png"))
    assert heat is not None and heat.shape[1] > 24 * 24
    assert main(["suggest", str(tmp_path / "nowhere")]) == 3


def test_lirm_suggest_after_reconstruction_uses_the_mesh(lego_capture, tmp_path, capsys):
    import shutil

    from lirm.engine.cli import main

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["reconstruct", str(capture), "--updates", "2", "--preset", "tiny", "--novel-views", "1",
                 "--render-size", "24", "--grid-resolution", "48"]) == 0
    capsys.readouterr()
    assert main(["suggest", str(capture), "--k", "2"]) == 0
    out = capsys.readouterr().out
    assert "surface: reconstruction after update 2" in out
    assert "1. azimuth" in out


def test_farthest_views_spread_round_the_object():
    from lirm.engine.guidance.next_views import farthest_views

    front = [orbit_camera(a, 20.0, 2.5, 64, 64, 50.0) for a in (-20.0, 0.0, 20.0)]
    ring = [orbit_camera(a, 20.0, 2.5, 64, 64, 50.0) for a in range(0, 360, 30)]
    first, second = farthest_views(front, ring, 2)
    assert camera_angles(ring[first])[0] == 180.0  # straight behind
    assert abs((camera_angles(ring[second])[0] - 180.0 + 180.0) % 360.0 - 180.0) >= 60.0  # not bunched next to it
    assert 6 not in farthest_views(front, ring, 3, exclude=(6,))  # already chosen
    assert farthest_views(front, ring[:2], 5) == [1, 0]  # no more than there are, 30° before 0°


def test_once_all_is_covered_the_next_view_goes_where_it_is_seen_most_obliquely(renderer):
    """Six cameras on the axes see every point of a sphere within 55°: binary coverage has nothing
    left to gain, but the corner directions are seen only at about 55°, and a corner camera sees them
    head-on."""
    sphere = trimesh.creation.icosphere(3, radius=0.6)
    coverage = SurfaceCoverage(renderer, sphere.vertices, sphere.faces, sphere.vertex_normals)
    try:
        axes = [orbit_camera(a, 0.0, 3.0, 96, 96, 40.0) for a in (0, 90, 180, 270)] + \
               [orbit_camera(0, e, 3.0, 96, 96, 40.0) for e in (90, -90)]
        assert (coverage.covered(axes) > 0).all()
        candidates = [orbit_camera(90, 0.0, 3.0, 96, 96, 40.0), orbit_camera(135, 35.26, 3.0, 96, 96, 40.0)]
        chosen, gains, first = greedy_views(coverage, axes, candidates, 2)
        assert chosen[0] == 1 and first[0] < 1e-6 < first[1]  # the axis camera again adds nothing
        binary, _, first_binary = greedy_views(coverage, axes, candidates, 2, graded=False)
        assert binary == [] and np.all(first_binary == 0)
    finally:
        coverage.release()


def test_suggest_speaks_in_units_says_what_each_move_is_from_and_stays_above_the_ground(lego_capture, tmp_path, capsys):
    """Issue 21, case 13: the lego was photographed only from above (a model on a table): no
    suggestion from below unless it can be turned over; distances carry their unit; each sentence
    says what it is relative to; the heat map has its axis titles and a colour legend."""
    import re
    import shutil

    import cv2

    from lirm.engine.cli import main

    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    assert main(["suggest", str(capture), "--k", "6"]) == 0
    captured = capsys.readouterr()
    assert "stands on something" in captured.err and "--can-turn" in captured.err
    elevations = [float(e) for e in re.findall(r"elevation (-?\d+)°", captured.out)]
    assert len(elevations) == 6 and min(elevations) >= 0
    assert "distances are in object radii" in captured.out and "radii: from your last photo" in captured.out
    assert "then, from view 1" in captured.out
    heat = cv2.imread(str(capture / "guidance" / "heat_map.png"))
    assert heat.shape[1] >= 24 * 24 + 60 + 100  # the map, the elevation axis and the legend
    assert main(["suggest", str(capture), "--k", "6", "--can-turn"]) == 0
    assert "stands on something" not in capsys.readouterr().err
