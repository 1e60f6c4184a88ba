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
    true mask, predicted radiance). Each environment gives a label and two rows, the truth above the
    export, on as many views as its first panel shows."""
    views = len(panels[0][2])
    blocks = [_banner(title, _view_row_width(panels[0][2]))]
    for name, exposure_ev, shown in panels:
        if len(shown) != views:
            continue
        truth_row, export_row = [], []
        for true_radiance, true_mask, radiance in shown:
            region = scored_pixels(true_mask)
            scaled = scale_to_truth(radiance, true_radiance, region) if region.any() else radiance
            truth_row.append(tonemap(np.asarray(true_radiance, np.float64), exposure_ev))
            export_row.append(tonemap(scaled, exposure_ev))
        image = np.concatenate([np.concatenate(truth_row, axis=1), np.concatenate(export_row, axis=1)], axis=0)
        image = (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
        scale = max(1, 256 // image.shape[0])  # small protocol views are enlarged to be looked at
        image = cv2.resize(image, (image.shape[1] * scale, image.shape[0] * scale), interpolation=cv2.INTER_NEAREST)
        blocks += [_banner(f"under {name}: truth above, export below", image.shape[1]), image]
    width = max(b.shape[1] for b in blocks)
    blocks = [np.pad(b, ((0, 0), (0, width - b.shape[1]), (0, 0)), constant_values=255) for b in blocks]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(np.concatenate(blocks), cv2.COLOR_RGB2BGR))
    return path


BANNER_HEIGHT = 22


def _view_row_width(shown) -> int:
    size = shown[0][0].shape
    return size[1] * len(shown) * max(1, 256 // (2 * size[0]))


def _banner(text: str, width: int) -> np.ndarray:
    banner = np.full((BANNER_HEIGHT, width, 3), 255, np.uint8)
    cv2.putText(banner, text[: max(8, width // 7)], (4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return banner
