"""Why a capture has no "as photographed" lighting, as the Lighting panel and `lirm refine` say it:
the capture stage's own reason (cut-outs show no background), or that it has not run yet."""

from __future__ import annotations

import json
import shutil

from lirm.engine.lighting.capture_lighting import missing_lighting_reason


def test_a_capture_without_a_lighting_estimate_says_why(lego_capture, tmp_path):
    # The lego's renders are cut-outs: no background to read the lighting from.
    assert missing_lighting_reason(lego_capture).startswith("no photo shows any background")
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    info = json.loads((capture / "capture.json").read_text())
    info["history"] = [entry for entry in info["history"] if entry.get("action") != "lighting"]
    (capture / "capture.json").write_text(json.dumps(info))
    assert "not estimated yet" in missing_lighting_reason(capture)
    (capture / "capture.json").write_text("{ not json")
    assert missing_lighting_reason(capture) == "its capture.json cannot be read"
