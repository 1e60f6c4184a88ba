"""The photos' EXIF focal length as a referee of COLMAP's model: pose again from it when they disagree.

COLMAP posing from a handful of photos sometimes settles on a wrong model whose cameras agree with
each other but not with the lens: on five of the fox's photos (every 13th) it registered 3 with a
focal length 1.53 x the true one and rotations 30 degrees off. Starting every camera from the EXIF
focal length instead (`ColmapConfig.use_exif_focal`) mended that case but, on other sparse subsets of
the same photos, broke as many models as it mended (README, "Captures"), so it is not the default.
What does hold: a model whose focal length is far from the lens's is wrong. So the posing runs as
before, and only when its focal length is off by more than `FOCAL_DISAGREEMENT` is it posed again
from the EXIF value; the second model is kept when it registers at least as many photos and agrees
with the lens within `FOCAL_AGREEMENT`, otherwise the first stays and the report says why.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from .colmap_posing import ColmapConfig, pose_with_colmap
from .records import ImageRecord, PosingResult

FOCAL_DISAGREEMENT = 1.25  # a model's focal length this many times the EXIF one (or its inverse): pose again
FOCAL_AGREEMENT = 1.10  # EXIF 35 mm figures are whole millimetres, and phones round them (2-4 %)


def focal_ratio(result: PosingResult, records: Sequence[ImageRecord]) -> float | None:
    """The median over registered photos with an EXIF focal length of the model's fx over it."""
    priors = {r.frame_id: r.focal_prior_px for r in records if r.focal_prior_px}
    ratios = [camera.fx / priors[f] for f, camera in result.cameras.items() if f in priors]
    if not ratios or len(ratios) < len(result.cameras) / 2:
        return None
    return float(np.median(ratios))


def disagrees(ratio: float | None, limit: float) -> bool:
    return ratio is not None and abs(math.log(ratio)) > math.log(limit)


def pose_again_if_focal_is_off(
    result: PosingResult,
    records: list[ImageRecord],
    capture_root: Path,
    work: Path,
    config: ColmapConfig,
    progress=None,
    cancel=None,
) -> tuple[PosingResult, str | None]:
    """`result` (COLMAP's model in `work`), or a model posed again from the EXIF focal length in its
    place; with a note for the capture's history when the check found something."""
    ratio = focal_ratio(result, records)
    if config.use_exif_focal or not disagrees(ratio, FOCAL_DISAGREEMENT):
        return result, None
    second_work = work.with_name(work.name + "-exif-focal")
    shutil.rmtree(second_work, ignore_errors=True)
    second = pose_with_colmap(records, capture_root, second_work, config=replace(config, use_exif_focal=True),
                              progress=progress, cancel=cancel)
    second_ratio = focal_ratio(second, records)
    first = f"COLMAP's model had a focal length {ratio:.2f} x the photos' EXIF one ({len(result.cameras)} photos registered)"
    if len(second.cameras) >= len(result.cameras) and second_ratio is not None and not disagrees(second_ratio, FOCAL_AGREEMENT):
        shutil.rmtree(work)
        second_work.rename(work)
        return second, (f"{first}; posed again from the EXIF focal length: {len(second.cameras)} registered, "
                        f"focal length {second_ratio:.2f} x the EXIF one")
    shutil.rmtree(second_work, ignore_errors=True)
    return result, (f"{first}; posing again from the EXIF focal length did no better ({len(second.cameras)} registered, "
                    f"focal length {'unknown' if second_ratio is None else f'{second_ratio:.2f} x'}): the first model is kept")
