"""Pictures of the relighting test (`lirm eval --pictures DIR`): for a few output views, the true
object under the relighting environment above the relit export, both as the display shows them
(the prediction after the test's per-channel scale), so that what the numbers say can be seen; and
the same under a second environment that lit none of the inputs either, where the set has one."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from lirm.renderer.tonemap import tonemap

from .relighting import scale_to_truth, scored_pixels


def write_relight_picture(path: Path, panels: list[tuple[str, float, list[tuple[np.ndarray, np.ndarray, np.ndarray]]]],
                          title: str) -> Path:
    """`panels`: per environment, (its name, the exposure, shown), and `shown` per view: (true radiance,
    true mask, predicted radiance). Each environment gives two rows, the truth above the export, on
    as many views as its first panel shows."""
    rows, names = [], []
    views = len(panels[0][2])
    for name, exposure_ev, shown in panels:
        if len(shown) != views:
            continue
        truth_row, export_row = [], []
        for true_radiance, true_mask, radiance in shown:
            region = scored_pixels(true_mask)
            scaled = scale_to_truth(radiance, true_radiance, region) if region.any() else radiance
            truth_row.append(tonemap(np.asarray(true_radiance, np.float64), exposure_ev))
            export_row.append(tonemap(scaled, exposure_ev))
        rows += [np.concatenate(truth_row, axis=1), np.concatenate(export_row, axis=1)]
        names.append(name)
    image = np.concatenate(rows, axis=0)
    image = (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    scale = max(1, 512 // image.shape[0])  # small protocol views are enlarged to be looked at
    image = cv2.resize(image, (image.shape[1] * scale, image.shape[0] * scale), interpolation=cv2.INTER_NEAREST)
    banner = np.full((22, image.shape[1], 3), 255, np.uint8)
    legend = "; ".join(f"truth, export under {name}" for name in names)
    cv2.putText(banner, f"{title}  (rows: {legend})"[:160], (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(np.concatenate([banner, image]), cv2.COLOR_RGB2BGR))
    return path
