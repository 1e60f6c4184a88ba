"""Does the material network know these photos? A check it makes on itself before the refinement
listens to it.

The network was trained on four kinds of built-in object under three procedural skies. On photos
like those, its metal is stable: mirror the photo, or brighten or darken the object by 15% (both are
among its training augmentations, so neither should change what a pixel is made of), and almost no
pixel's metallic moves by more than 0.3. On objects unlike its training's it guesses, and the guesses
move: measured on the held-out sets' 16 input views (stop 81, the shipped weights), 0.2-1.0% of the
object's pixels move on each of the 8 held-out synthetic objects, 2.7-14.6% on each of the 7 glTF
models (where it saw metal on a plain white bunny and none on an all-metal monkey). The refinement
holds its materials to the network only on photos where fewer than `LIMIT` of the pixels move.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .material_net import MaterialNet, PixelMaterials, object_exposure, predict_materials

GAINS = (0.85, 1.0, 1.15)  # the training's exposure jitter is U(0.85, 1.15)
SPREAD = 0.3  # a pixel whose metallic moves by more than this under the variations is unstable
# The share of unstable object pixels up to which the network is trusted: between the synthetic
# objects' 1.0% at most and the glTF models' 2.7% at least (stop 81), nearer the first.
LIMIT = 0.02


@dataclass(frozen=True)
class Familiarity:
    unstable_fraction: float  # of the object's pixels (mask > 0.5) over all the photos
    limit: float = LIMIT
    # The prediction on the photos as they are (one of the variants), so that a caller that trusts
    # the network need not predict again.
    as_photographed: PixelMaterials | None = field(default=None, repr=False, compare=False)

    @property
    def familiar(self) -> bool:
        return self.unstable_fraction < self.limit

    def describe(self) -> str:
        verdict = "used" if self.familiar else "not used: these photos are unlike what it was trained on"
        return (f"the material network {verdict} ({100 * self.unstable_fraction:.1f}% of the object's pixels change their metal "
                f"when a photo is mirrored or its exposure moved 15%; it is trusted below {100 * self.limit:.0f}%)")


def material_net_familiarity(net: MaterialNet, images: np.ndarray, masks: np.ndarray) -> Familiarity:
    """How stable the network's metallic is on these photos ((V, H, W, 3) display sRGB on white, (V, H, W)
    masks) under a mirror flip and the training's exposure range."""
    images, masks = np.asarray(images, np.float32), np.asarray(masks, np.float32)
    inside = masks > 0.5
    if not inside.any():
        return Familiarity(1.0)
    low = high = as_photographed = None
    for mirrored in (False, True):
        for gain in GAINS:
            varied = images if gain == 1.0 else object_exposure(images, masks, gain)  # (1.0: the photos as they are)
            m = masks
            if mirrored:
                varied, m = varied[:, :, ::-1], m[:, :, ::-1]
            predicted = predict_materials(net, np.ascontiguousarray(varied), np.ascontiguousarray(m))
            if not mirrored and gain == 1.0:
                as_photographed = predicted
            metallic = predicted.metallic[:, :, ::-1] if mirrored else predicted.metallic
            low = metallic if low is None else np.minimum(low, metallic)
            high = metallic if high is None else np.maximum(high, metallic)
    return Familiarity(float(((high - low)[inside] > SPREAD).mean()), as_photographed=as_photographed)
