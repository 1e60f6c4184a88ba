"""Paired differences over objects: the mean, its 95% Student-t interval and the verdict."""

from __future__ import annotations

import math

import pytest

from lirm.engine.evaluation.paired_difference import LOSES, WINS, WITHIN_NOISE, paired_difference


def test_interval_matches_the_textbook_t_interval():
    a, b = [20.0, 21.0, 19.5, 22.0], [19.0, 20.5, 19.5, 21.0]  # differences 1, 0.5, 0, 1
    d = paired_difference(a, b)
    mean, sd = 0.625, math.sqrt(((0.375**2) * 2 + 0.125**2 + 0.625**2) / 3)
    half = 3.182446305284263 * sd / 2.0  # t(0.975, 3) * sd / sqrt(4)
    assert d.mean == pytest.approx(mean) and d.low == pytest.approx(mean - half) and d.high == pytest.approx(mean + half)
    assert d.objects == 4 and d.better == 3 and d.verdict == WITHIN_NOISE  # one object did not move: not sure


def test_verdicts_and_lower_is_better():
    assert paired_difference([2.0, 2.1, 1.9, 2.0], [1.0, 1.0, 1.1, 0.9]).verdict == WINS
    assert paired_difference([1.0, 1.0, 1.1, 0.9], [2.0, 2.1, 1.9, 2.0]).verdict == LOSES
    # Chamfer distance: smaller is better, so a's smaller distances win.
    d = paired_difference([0.04, 0.05, 0.045], [0.06, 0.07, 0.066], lower_is_better=True)
    assert d.mean > 0 and d.verdict == WINS


def test_missing_scores_are_left_out_and_one_object_decides_nothing():
    d = paired_difference([1.0, None, float("inf"), 3.0], [0.0, 1.0, 2.0, 1.0])
    assert d.objects == 2 and d.mean == pytest.approx(1.5)
    one = paired_difference([5.0], [1.0])
    assert one.objects == 1 and one.low == one.high == 4.0 and one.verdict == WITHIN_NOISE
    assert paired_difference([None], [1.0]) is None
