"""The Capture panel's list of views in a real window: a photo that failed says so in a word, its
whole reason on hover, and the photos' names keep their room. Before, one unposed photo's reason
(a couple of hundred characters since the poses are checked against the outlines) widened the
pose column to its length and cut every photo's name to two letters."""

from __future__ import annotations

import json
import shutil

import pytest

from lirm.engine.capture.pipeline import LEFT_OUT

LONG_REASON = (f"{LEFT_OUT} its pose disagreed with the other photos' outlines (31% of the object's outline fell where "
               "they see none): structure from motion likely put it on the wrong side of an object that looks alike "
               "from two sides")


@pytest.mark.display
@pytest.mark.slow
def test_unposed_views_leave_the_names_their_room(lego_capture, tmp_path, scripted_session):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    data = json.loads((capture / "capture.json").read_text())
    left_out = data["frames"][-1]["frame_id"]
    data["frames"][-1]["pose_status"] = LONG_REASON
    data["cameras"].pop(left_out)
    (capture / "prepared" / f"{left_out}.npz").unlink()
    data["frames"][-2]["mask_status"] = "touches the border on all four sides: it probably includes background"
    data["reports"] = data.get("reports", []) + [
        {"path": "/photos/IMG_0031.NEF", "accepted": False, "reason": "camera raw (NEF) is not developed here: ..."},
        {"path": "/photos/notes.txt", "accepted": False, "reason": "side file, not a photo"}]
    (capture / "capture.json").write_text(json.dumps(data))
    result = scripted_session([
        {"frames": 2}, {"action": "open_capture", "args": [str(capture)]}, {"frames": 3},
        {"report_widgets": True}, {"screenshot": "views"}, {"quit": True}])
    names = {k: v for k, v in result["widgets"].items() if k.startswith("view_")}
    assert len(names) == len(data["frames"]), sorted(names)
    widths = [x1 - x0 for x0, _, x1, _ in names.values()]
    # "r_35.png" is about 60 pixels in the app's font; the long reason had left the column 14.
    assert min(widths) >= 80, widths
    # The file an import did not take is listed (folded), the side file is not.
    assert "skipped_files" in result["widgets"]
