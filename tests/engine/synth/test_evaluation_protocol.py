"""The supplementary's test protocol: 3 rings x 16 azimuths at FoV 50, inputs from the 20/40 degree
rings in sets of 4, 12 outputs never used as inputs, the same every time for a seed."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.synth.evaluation_protocol import ProtocolConfig, protocol_views


def test_cameras_follow_the_protocol():
    views = protocol_views(ProtocolConfig(size=64))
    assert len(views.cameras) == 48
    assert sorted(set(views.elevations_deg)) == [0.0, 20.0, 40.0]
    assert len(set(views.azimuths_deg)) == 16
    for cam in views.cameras:
        assert cam.fov_x_deg == pytest.approx(50.0)
        # The bounding sphere just fits: its silhouette's half angle equals half the field of view.
        distance = np.linalg.norm(cam.center)
        assert np.degrees(np.arcsin(1.0 / distance)) == pytest.approx(25.0, abs=1e-6)
        assert np.allclose(cam.forward, -cam.center / distance, atol=1e-9)  # looking at the origin


def test_inputs_and_outputs_are_disjoint_seeded_and_on_the_right_rings():
    a = protocol_views(ProtocolConfig(size=64), object_index=3)
    b = protocol_views(ProtocolConfig(size=64), object_index=3)
    c = protocol_views(ProtocolConfig(size=64), object_index=4)
    assert a.input_sets == b.input_sets and a.outputs == b.outputs
    assert a.input_sets != c.input_sets
    inputs = [i for s in a.input_sets for i in s]
    assert [len(s) for s in a.input_sets] == [4, 4, 4, 4] and len(set(inputs)) == 16
    assert all(a.elevations_deg[i] in (20.0, 40.0) for i in inputs)
    assert len(a.outputs) == 12 and not set(a.outputs) & set(inputs)
    with pytest.raises(ValueError, match="rings have 32"):
        protocol_views(ProtocolConfig(input_sets=9))
