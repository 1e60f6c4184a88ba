""""As photographed" in the window (issue 19): a capture's own lighting estimate is offered first in
the Lighting panel, lights the viewport when picked, and the panel shows the estimated panorama.
The screenshots are left in the test's folder (out/) to look at."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from lirm.engine.lighting.capture_lighting import CaptureLighting, CaptureLightingConfig
from lirm.renderer.procedural_environments import make_procedural_environment

pytestmark = [pytest.mark.display, pytest.mark.slow]


def _estimate_into(capture) -> str:
    """A lighting estimate as the capture stage writes it: the sky, its upper half unseen."""
    environment = make_procedural_environment("sky", width=128)
    observed = np.zeros((64, 128))
    observed[32:] = 5
    CaptureLighting(environment, observed, np.zeros((64, 128)), 8, CaptureLightingConfig()).save(capture)
    return str((capture / "lighting" / "as_photographed.hdr").resolve())


def test_the_capture_lighting_is_offered_and_lights_the_viewport(lego_capture, tmp_path, scripted_session):
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    panorama = _estimate_into(capture)
    views = sorted(p.stem for p in (capture / "prepared").glob("*.npz"))
    result = scripted_session([
        {"frames": 2}, {"action": "open_capture", "args": [str(capture)]},
        {"action": "select_views", "args": [views[:4]]}, {"action": "run_update"}, {"wait": "jobs"},
        {"action": "set_environment", "args": ["studio"]}, {"frames": 3}, {"screenshot": "studio"},
        {"action": "set_environment", "args": [panorama]}, {"frames": 3}, {"screenshot": "as_photographed"},
        {"report_widgets": True},
        {"action": "set_real_size", "args": [0.2]}, {"wait": "jobs"}, {"frames": 3}, {"wait": "jobs"}, {"frames": 3},
        {"screenshot": "real_size"},
        {"quit": True}])
    assert result["viewport"]["environment_lit"] == panorama
    assert result["viewport"]["tonemapper"] == "aces"  # the estimate was read through the ACES curve
    # Viewport guides (issue 21, case 7): with the real height stated, the scale bar is in real units.
    value, unit = result["viewport"]["scale_bar"].split()
    metres = float(value) * {"m": 1.0, "cm": 0.01, "mm": 0.001}[unit]
    assert 0.01 <= metres <= 0.1, result["viewport"]  # a round length shorter than the 20 cm object that fills the view

    assert not [m for m in result["messages"] if m["level"] == "error"], result["messages"]
    x0, y0, x1, y1 = (int(round(v)) for v in result["widgets"]["viewport"])
    studio, photographed = (cv2.imread(result["screenshots"][name])[y0 + 2:y1 - 2, x0 + 2:x1 - 2].astype(int)
                            for name in ("studio", "as_photographed"))
    assert np.abs(studio - photographed).mean() > 5  # the viewport is lit (and backed) by the estimate now
    # The Lighting panel (right of the viewport) shows the estimated panorama only for "as photographed".
    before, after = (cv2.imread(result["screenshots"][name])[:, x1 + 4:].astype(int) for name in ("studio", "as_photographed"))
    changed = np.abs(before - after).max(axis=-1) > 30
    assert changed.sum() > 20_000, changed.sum()  # a panorama of about 230 x 115 pixels appeared


def test_a_capture_read_through_srgb_is_shown_through_srgb_under_its_own_light(lego_capture, tmp_path, scripted_session):
    """A capture on a clipped white backdrop is read through plain sRGB (camera_response.py): under
    its own light the viewport shows the asset through that curve, as the photos look (under any
    other environment through the product's ACES curve: the test above)."""
    capture = tmp_path / "capture"
    shutil.copytree(lego_capture, capture)
    observed = np.zeros((64, 128))
    observed[32:] = 5
    CaptureLighting(make_procedural_environment("studio", width=128), observed, np.ones((64, 128)), 8,
                    CaptureLightingConfig(response="srgb")).save(capture)
    panorama = str((capture / "lighting" / "as_photographed.hdr").resolve())
    result = scripted_session([
        {"frames": 2}, {"action": "open_capture", "args": [str(capture)]},
        {"action": "set_environment", "args": ["studio"]}, {"frames": 3}, {"screenshot": "studio"},
        {"action": "set_environment", "args": [panorama]}, {"frames": 3}, {"screenshot": "own_light"},
        {"report_widgets": True}, {"quit": True}])
    assert result["viewport"]["environment_lit"] == panorama and result["viewport"]["tonemapper"] == "linear"
    # The same studio light behind, through the other curve: the backdrop is shown differently.
    x0, y0, x1, y1 = (int(round(v)) for v in result["widgets"]["viewport"])
    studio, own = (cv2.imread(result["screenshots"][name])[y0 + 2:y1 - 2, x0 + 2:x1 - 2].astype(int) for name in ("studio", "own_light"))
    assert np.abs(studio - own).mean() > 5
