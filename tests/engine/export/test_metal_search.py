"""The per-texel choice between material hypotheses (metal_search.py)."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.export.metal_search import AS_FITTED, DIELECTRIC, METAL, choose_hypotheses, texel_of


def _pixels(count: int = 6000, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).random((count, 2))


def test_each_texel_takes_the_hypothesis_that_explains_its_neighbourhood_best():
    uv = _pixels()
    left = uv[:, 0] < 0.5
    noise = np.random.default_rng(1).random(len(uv)) * 0.02
    as_fitted = 0.10 + noise
    dielectric = np.where(left, 0.20, 0.05) + noise  # clearly better on the right
    metal = np.where(left, 0.03, 0.20) + noise  # clearly better on the left
    choice = choose_hypotheses([as_fitted, dielectric, metal], uv, 16, sigma=1.0, margin=0.1)
    assert (choice.choice[:, :7] == METAL).all() and (choice.choice[:, 9:] == DIELECTRIC).all()
    covered = np.ones((16, 16), bool)
    # Only where the neighbourhood straddles the two halves may the field's hypothesis stay.
    assert choice.share(AS_FITTED, covered) == pytest.approx((choice.choice[:, 7:9] == AS_FITTED).mean() * 2 / 16)


def test_the_fields_own_hypothesis_stays_unless_another_is_clearly_better():
    uv = _pixels()
    as_fitted = np.full(len(uv), 0.100)
    slightly = np.full(len(uv), 0.095)  # 5% lower: within the 10% margin
    choice = choose_hypotheses([as_fitted, slightly, slightly + 0.01], uv, 16, margin=0.1)
    assert (choice.choice == AS_FITTED).all()
    assert (choose_hypotheses([as_fitted, slightly, slightly + 0.01], uv, 16, margin=0.0).choice == DIELECTRIC).all()


def test_texels_too_few_pixels_judge_keep_the_fields_hypothesis():
    uv = _pixels(40)  # 40 pixels over 64 x 64 texels: no neighbourhood holds one
    better = np.zeros(len(uv))
    choice = choose_hypotheses([np.ones(len(uv)), better, better], uv, 64, sigma=0.0, min_pixels=2.0)
    assert (choice.choice == AS_FITTED).all()
    with pytest.raises(ValueError):
        choose_hypotheses([better, better], uv, 64)


def test_texels_are_found_as_the_fit_reads_the_atlas():
    # Row from v, column from u; the far edge stays inside.
    assert texel_of(np.array([[0.0, 0.0], [0.99, 0.0], [0.0, 0.99], [1.0, 1.0]]), 4).tolist() == [0, 3, 12, 15]
