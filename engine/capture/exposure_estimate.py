"""Photos exposed apart with nothing in their EXIF to say so: each one's exposure read from the
surroundings the photos share.

A photo whose EXIF was stripped (sent through a messenger, exported by an editor, a screenshot) says
nothing of its exposure, so exposure_match.py cannot bring it to the others'. But every posed photo's
background is a view of the same surroundings: followed through the lighting estimate's proxy (the
support plane and the far sphere, capture_lighting.background_samples) onto one panorama, two photos
that saw the same patch of floor or wall saw the same radiance, and what differs between them is
their exposure. Per photo and panorama texel, the mean log luminance of its unclipped, not-too-dark
background pixels (through the camera curve); per pair of photos, the median difference over the
texels both saw (robust to the patches the proxy misplaces and to a reflection that moves with the
view); then the exposures that agree best with all pairs (weighted least squares, weights the shared
texels, the mean fixed at 0).

The same comparison channel by channel gives each photo's white balance (a phone balances every shot
on its own too, and no EXIF tag says by how much): per photo, its red, green and blue offsets from its
own mean, relative to the shoot's average balance. The surroundings' sheen that biases the exposure is
white, so the balance is read far more closely (0.01-0.02 EV at one balance, the demo shoot and the
fox).

Returned as "stops" in the same sense as the EXIF's (larger: more exposed), so exposure_match's gains
take them as they take the EXIF's. Estimated spreads up to `ESTIMATE_NOISE_STOPS` are what photos at
one exposure give (the proxy's parallax, view-dependent floors), so those are not matched. Nor is an
estimate whose pairs disagree with each other by more than `MAX_RESIDUAL_STOPS` (median): there the
proxy puts different things in one place (a patterned wall near the object, which the proxy places
far or flat), and matching by it would brighten photos that were not darker.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.lighting.camera_response import display_to_radiance
from lirm.engine.lighting.capture_lighting import CaptureLightingConfig, background_samples, proxy_radius_of
from lirm.renderer.procedural_environments import LUMINANCE_WEIGHTS as _LUMINANCE

# Spreads this small are the estimate's own noise, not an exposure that moved. Photos at one exposure
# gave 0.00-0.05 EV of a real HDRI's surroundings (tests/engine/capture/test_exposure_estimate.py) and
# 0.22 EV on the demo shoot: its floor's sheen is brighter from the sun's side, a smooth swing with the
# azimuth that nothing in the surroundings tells from an exposure. 1 EV apart, the demo's photos come
# back within 0.14 EV.
ESTIMATE_NOISE_STOPS = 0.3
# Pairs that disagree by more than this with the fitted exposures (median) mean the surroundings were
# misplaced: 0.01-0.04 EV on rendered shoots, 0.22 on five photos of the fox before its wallpaper.
MAX_RESIDUAL_STOPS = 0.1
# Colour offsets this small are the estimate's noise (0.01-0.02 EV measured at one white balance): a
# spread within it is one balance, left alone.
COLOUR_NOISE_STOPS = 0.05
# Display values below this are mostly the 8-bit steps and the curve's toe; above the clip level, a bound.
DARK_LEVEL = 0.04
MIN_SHARED_TEXELS = 12  # a pair of photos that shares fewer says nothing of their exposures


@dataclass(frozen=True)
class ExposureEstimate:
    stops: dict[str, float]  # per frame, relative (mean 0; larger: more exposed)
    pairs: int  # pairs of photos that shared enough surroundings
    residual_stops: float  # the median disagreement of a pair with the fitted exposures
    # Per frame, log2 of its red, green, blue against its own mean, less the shoot's average: a photo
    # balanced warmer than the others has red > 0 > blue. Dividing by 2^offset balances it as the shoot.
    colour_stops: dict[str, tuple[float, float, float]]

    @property
    def spread(self) -> float:
        return max(self.stops.values()) - min(self.stops.values())

    @property
    def colour_spread(self) -> float:
        return colour_spread(self.colour_stops)

    @property
    def colour_worth_matching(self) -> bool:
        return self.reliable and self.colour_spread > COLOUR_NOISE_STOPS

    @property
    def reliable(self) -> bool:
        return self.residual_stops <= MAX_RESIDUAL_STOPS

    @property
    def worth_matching(self) -> bool:
        """Whether the photos should be brought to one exposure by this estimate (module doc)."""
        return self.reliable and self.spread > ESTIMATE_NOISE_STOPS


def colour_spread(colour_stops) -> float:
    """The widest spread of one channel's offset over the photos (stops), of per-frame (r, g, b) offsets."""
    offsets = np.array(list(colour_stops.values()))
    return float((offsets.max(0) - offsets.min(0)).max())


def estimate_exposure_stops(images: dict, masks: dict, cameras: dict, config: CaptureLightingConfig,
                            support_plane: tuple[np.ndarray, float] | None = None, cancel=None) -> ExposureEstimate | None:
    """Each photo's exposure relative to the others' from their backgrounds (module doc): `images`,
    `masks`, `cameras` and `support_plane` as for capture_lighting.estimate_capture_lighting, read
    through `config.response`. None when fewer than two photos show background, or when the photos
    that do are not all joined by shared surroundings (an exposure with nothing to compare is unknown)."""
    frames = [f for f in sorted(cameras) if f in images and f in masks]
    if len(frames) < 2:
        return None
    radius = proxy_radius_of({f: cameras[f] for f in frames}, config)
    texels = (config.width // 2) * config.width
    means, seen = [], []
    for f in frames:
        if cancel is not None and cancel():
            raise InterruptedError("cancelled while estimating the photos' exposures")
        texel, display = background_samples(images[f], masks[f], cameras[f], config, radius, support_plane)
        usable = (display.max(1) < config.clip_level) & (display.min(1) > DARK_LEVEL)
        radiance = display_to_radiance(display[usable], config.response)
        texel = texel[usable]
        count = np.bincount(texel, minlength=texels)
        # log2 of the luminance, then of red, green and blue: one column each
        logs = np.log2(np.maximum(np.concatenate([radiance @ _LUMINANCE[:, None], radiance], 1), 1e-8))
        total = np.stack([np.bincount(texel, logs[:, k], texels) for k in range(4)], 1)
        means.append(total / np.maximum(count, 1)[:, None])
        seen.append(count >= 2)  # one pixel in a texel is too much at the mercy of a stray edge
    rows, targets, weights = [], [], []
    for i in range(len(frames)):
        for j in range(i + 1, len(frames)):
            shared = seen[i] & seen[j]
            n = int(shared.sum())
            if n >= MIN_SHARED_TEXELS:
                rows.append((i, j))
                targets.append(np.median(means[i][shared] - means[j][shared], axis=0))
                weights.append(float(n))
    if not rows or not _all_joined(len(frames), rows):
        return None
    targets = np.array(targets)
    fitted = np.stack([_fit_exposures(len(frames), rows, targets[:, k], np.array(weights)) for k in range(4)], 1)
    stops = fitted[:, 0]
    residual = float(np.median([abs(stops[i] - stops[j] - d) for (i, j), d in zip(rows, targets[:, 0])]))
    colour = fitted[:, 1:] - fitted[:, 1:].mean(1, keepdims=True)
    colour -= colour.mean(0)  # the shoot's average balance is kept
    return ExposureEstimate({f: float(s) for f, s in zip(frames, stops)}, len(rows), residual,
                            {f: tuple(float(v) for v in c) for f, c in zip(frames, colour)})


def _fit_exposures(count: int, pairs: list[tuple[int, int]], differences: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The exposures s minimising sum w (s_i - s_j - d_ij)^2 with mean(s) = 0."""
    a = np.zeros((len(pairs) + 1, count))
    for k, (i, j) in enumerate(pairs):
        a[k, i], a[k, j] = 1.0, -1.0
    a[-1] = 1.0  # the gauge: only differences are seen
    root = np.sqrt(np.append(weights / weights.max(), 1.0))
    solution, *_ = np.linalg.lstsq(a * root[:, None], np.append(differences, 0.0) * root, rcond=None)
    return solution


def _all_joined(count: int, pairs: list[tuple[int, int]]) -> bool:
    parent = list(range(count))

    def root(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i, j in pairs:
        parent[root(i)] = root(j)
    return len({root(k) for k in range(count)}) == 1
