"""The panels' small helpers (app/panels/common.py)."""

from __future__ import annotations

from lirm.app.panels.common import format_seconds, short_status
from lirm.engine.capture.colmap_posing import STATUS_NOT_REGISTERED, STATUS_SEPARATE_MODEL
from lirm.engine.capture.pipeline import LEFT_OUT

LONG_REASON = f"{LEFT_OUT} its pose disagreed with the other photos' outlines (31% ...): structure from motion ..."


def test_a_status_is_cut_to_its_head():
    assert short_status(LONG_REASON) == "left out"
    assert short_status(STATUS_NOT_REGISTERED) == "not registered"
    assert short_status("missing: the mask file was deleted") == "missing"
    assert short_status("ok") == "ok" and short_status("empty: no object found in this view") == "empty"
    # A head that is itself long says nothing rather than half a sentence ("registered in a ..."),
    # and the panel then shows its own word for a failure.
    assert short_status(STATUS_SEPARATE_MODEL) == "" and short_status("") == ""


def test_durations_read_in_milliseconds_below_a_tenth_of_a_second():
    assert format_seconds(0.0034) == "3 ms" and format_seconds(0.41) == "0.41 s" and format_seconds(12.0) == "12.00 s"
