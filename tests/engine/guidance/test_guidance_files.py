"""suggestions.json describes the heat map it holds (the app draws the view sphere from it)."""

from __future__ import annotations

import json

import numpy as np

from lirm.engine.guidance.next_views import CandidateConfig
from lirm.engine.guidance.suggest import CaptureSuggestions, write_guidance


def test_the_heat_map_rows_match_the_elevations_listed_when_views_from_below_are_left_out(tmp_path):
    """An object standing on something gets no candidates below it: the rows written are the ones the
    heat map has (the app's Guidance panel failed on a 9-row map listed with 10 elevations)."""
    above = CandidateConfig(elevations_deg=tuple(e for e in CandidateConfig().elevations_deg if e >= 0.0))
    columns = int(360 / above.azimuth_step_deg)
    heat = np.random.default_rng(0).random((len(above.elevations_deg), columns))
    result = CaptureSuggestions([], heat, 0.5, 0.5, np.zeros(4, np.int32), "test", [], np.zeros((4, 3), np.float32),
                                np.zeros((1, 3), np.int32), None, above)
    written = json.loads(write_guidance(tmp_path, result)["suggestions"].read_text())["heat_map"]
    assert len(written["elevations_deg"]) == len(written["gain"]) == len(above.elevations_deg)
    assert min(written["elevations_deg"]) >= 0.0 and len(written["gain"][0]) == columns
