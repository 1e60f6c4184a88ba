"""Plain backdrops: product shots on a white (or any one-colour) sweep or lightbox.

The automatic masks are seeded by sparse points and told the object from its surroundings by
colour models (auto_mask.py). On a plain backdrop both fail: the backdrop carries no features, so
the only plane among the points is the object's own base (the lego's plate, taken for the floor
and left out of every mask), and a white backdrop beside white or grey parts of the object gives
GrabCut two colour models that overlap (README, "Captures": the lego on white, IoU 0.56 over 44
views). But such a backdrop says where it is by itself: the photo's border is one smooth colour
field (a sweep lit from above is a gradient, a lens vignettes it), and every pixel of that field
that joins the border through pixels of the same field is backdrop.

Per photo, a quadratic in the pixel's position is fitted per CIELAB channel to the border strip's
pixels, robustly (the object may cross the border). The backdrop is plain when the fit explains
most of the strip within a few units of colour difference (JPEG noise and grain are 1-2; a
textured table or a patterned wall are far above). Its pixels: those within `match_tolerance` of
the fitted field, split into those joined to the border and farther than `definite_margin` from
anything else (definite backdrop) and the rest (the backdrop seen through a gap of the object, an
object part of the backdrop's colour, the band along the outline: left to the colour models and
the visual hull).

A smooth colour field at the border is not proof: a dark gravel floor at night, or a floor far
enough away to blur, fits it as well as a sweep (every synthetic shoot under the night HDRI passed
that test). What a plain backdrop cannot have is texture, and a floor's texture shows as specks the
field does not explain (the gravel's pebbles: 450-900 small islands over 3-10% of a 640-pixel
photo, against 0-18 covering under 0.05% on the lego shot on white), so a photo counts as plain
only when such specks cover almost none of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import cv2
import numpy as np


__all__ = ["BACKDROP", "BACKDROP_COLOURED", "PlainBackdropConfig", "backdrop_map", "plain_backdrop_capture"]

# Values of a backdrop map: not backdrop (0), the backdrop's colour but not joined to the border
# (1), backdrop joined to the border (2).
BACKDROP_COLOURED, BACKDROP = 1, 2


@dataclass
class PlainBackdropConfig:
    # Width of the border strip the field is fitted to (fraction of the photo's long side).
    border: float = 0.03
    # The field explains a border pixel when their CIELAB difference (dE76) is below this.
    fit_tolerance: float = 5.0
    # The backdrop is plain when the field explains at least this share of the border strip (the
    # rest may be the object running out of the picture, or a shadow).
    plain_fraction: float = 0.8
    # A pixel within this dE76 of the field has the backdrop's colour.
    match_tolerance: float = 6.0
    # Backdrop pixels nearer than this to anything else (fraction of the long side) are not definite.
    definite_margin: float = 0.01
    # The field is fitted and matched on a copy of this long side (the masks are then brought back
    # to full size; the auto masks work at 240-480 px anyway).
    long_side: int = 640
    # Texture on the backdrop: islands that are not the backdrop's colour, each under
    # `speck_size` of the photo, may cover at most `max_speck_share` of it.
    speck_size: float = 0.005
    max_speck_share: float = 0.005
    # A capture counts as shot on a plain backdrop when at least this share of its photos are.
    capture_fraction: float = 0.75
    # Off (the capture is masked as before) when False.
    enabled: bool = True


def _basis(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)


def _fit_field(lab: np.ndarray, strip: np.ndarray, tolerance: float) -> tuple[np.ndarray, float]:
    """(6 x 3 coefficients of the quadratic field, share of the strip it explains). Fitted to all
    of the strip, then to its best 70%, then to the pixels within twice the tolerance: what crosses
    the border (the object, a shadow) must not pull the field toward itself."""
    h, w = strip.shape
    ys, xs = np.nonzero(strip)
    basis = _basis(xs / max(w - 1, 1) * 2.0 - 1.0, ys / max(h - 1, 1) * 2.0 - 1.0)
    colours = lab[ys, xs]
    keep = np.ones(len(xs), bool)
    coeffs = np.zeros((6, 3))
    for round_ in range(3):
        if keep.sum() < 12:
            return coeffs, 0.0
        coeffs, *_ = np.linalg.lstsq(basis[keep], colours[keep], rcond=None)
        residual = np.linalg.norm(basis @ coeffs - colours, axis=1)
        keep = residual <= (np.quantile(residual, 0.7) if round_ == 0 else 2.0 * tolerance)
    return coeffs, float(np.mean(residual < tolerance))


def _speck_share(not_backdrop: np.ndarray, speck_size: float) -> float:
    """Share of the photo covered by small islands of `not_backdrop` (each under `speck_size` of it)."""
    _, _, stats, _ = cv2.connectedComponentsWithStats(not_backdrop.astype(np.uint8), connectivity=8)
    areas = stats[1:, cv2.CC_STAT_AREA]
    return float(areas[areas < speck_size * not_backdrop.size].sum()) / not_backdrop.size


def backdrop_map(image: np.ndarray, config: PlainBackdropConfig = PlainBackdropConfig()) -> np.ndarray | None:
    """The photo's backdrop map (uint8, the photo's size: 0, BACKDROP_COLOURED or BACKDROP), or None
    when its backdrop is not plain. image: RGB uint8."""
    img = np.asarray(image)[:, :, :3]
    h, w = img.shape[:2]
    scale = min(1.0, config.long_side / max(h, w))
    sw, sh = max(int(round(w * scale)), 8), max(int(round(h * scale)), 8)
    small = cv2.resize(img, (sw, sh), interpolation=cv2.INTER_AREA) if (sw, sh) != (w, h) else img
    lab = cv2.cvtColor(small.astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB)
    b = max(int(round(config.border * max(sw, sh))), 2)
    strip = np.zeros((sh, sw), bool)
    strip[:b], strip[-b:], strip[:, :b], strip[:, -b:] = True, True, True, True
    coeffs, share = _fit_field(lab, strip, config.fit_tolerance)
    if share < config.plain_fraction:
        return None
    yy, xx = np.mgrid[0:sh, 0:sw].astype(np.float64)
    field = _basis(xx / max(sw - 1, 1) * 2.0 - 1.0, yy / max(sh - 1, 1) * 2.0 - 1.0) @ coeffs
    matches = np.linalg.norm(field - lab, axis=-1) < config.match_tolerance
    n, labels = cv2.connectedComponents(matches.astype(np.uint8), connectivity=4)
    joined = np.zeros(n, bool)
    joined[np.unique(labels[strip & matches])] = True
    joined[0] = False
    backdrop = joined[labels]
    if _speck_share(~backdrop, config.speck_size) > config.max_speck_share:
        return None
    # Definite only away from anything else: a white part of the object blown out by a highlight has
    # the backdrop's colour where it touches the outline (the lego's plate edge, 0.8% of one view's
    # object); kept uncertain, the colour models and the other views decide there.
    r = max(int(round(config.definite_margin * max(sw, sh))), 1)
    deep = cv2.erode(backdrop.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))) > 0
    out = np.where(matches, BACKDROP_COLOURED, 0).astype(np.uint8)
    out[deep] = BACKDROP
    if (sw, sh) != (w, h):
        out = cv2.resize(out, (w, h), interpolation=cv2.INTER_NEAREST)
    return out


def plain_backdrop_capture(images: Mapping[str, np.ndarray],
                           config: PlainBackdropConfig = PlainBackdropConfig()) -> dict[str, np.ndarray] | None:
    """Backdrop maps of the photos (frame id -> map; photos whose backdrop is not plain are left
    out) when at least `capture_fraction` of them are shot on a plain backdrop, else None: one
    photo with a plain patch of wall behind the object is not a studio shoot."""
    if not config.enabled or not images:
        return None
    maps = {f: backdrop_map(image, config) for f, image in images.items()}
    plain = {f: m for f, m in maps.items() if m is not None}
    return plain if len(plain) >= config.capture_fraction * len(images) else None
