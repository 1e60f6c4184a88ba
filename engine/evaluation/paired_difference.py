"""Is one method better than another on the same objects, or within noise? The mean of the
per-object differences with a 95% Student-t interval: on a handful of held-out objects a difference
of a few hundredths of a dB means nothing unless the objects agree on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

WINS, LOSES, WITHIN_NOISE = "wins", "loses", "within noise"


@dataclass(frozen=True)
class PairedDifference:
    mean: float  # mean over objects of (a - b), signed so that positive = a better
    low: float  # the 95% interval of that mean (equal to mean when there is one object)
    high: float
    objects: int
    better: int  # objects on which a is better

    @property
    def verdict(self) -> str:
        """'wins' when the whole interval is above 0, 'loses' when below, else 'within noise'."""
        if self.objects < 2:
            return WITHIN_NOISE  # one object says nothing about the next
        return WINS if self.low > 0 else LOSES if self.high < 0 else WITHIN_NOISE

    def to_dict(self) -> dict:
        return {"mean": self.mean, "low": self.low, "high": self.high, "objects": self.objects, "better": self.better,
                "verdict": self.verdict}


def paired_difference(a: list[float | None], b: list[float | None], lower_is_better: bool = False,
                      confidence: float = 0.95) -> PairedDifference | None:
    """a and b: one score per object, same order. Objects where either is missing or not finite are
    left out; None when none is left."""
    pairs = [(x, y) for x, y in zip(a, b) if x is not None and y is not None and math.isfinite(x) and math.isfinite(y)]
    if not pairs:
        return None
    d = np.array([y - x if lower_is_better else x - y for x, y in pairs], np.float64)
    mean = float(d.mean())
    if len(d) < 2:
        return PairedDifference(mean, mean, mean, 1, int(d[0] > 0))
    half = float(stats.t.ppf(0.5 + confidence / 2, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d)))
    return PairedDifference(mean, mean - half, mean + half, len(d), int((d > 0).sum()))
