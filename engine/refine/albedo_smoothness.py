"""The albedo changes little over a short step on the surface (losses.albedo_smooth; README: what it
was worth), after nvdiffrec's smoothness of its material field.

Why: the PBR term shades with the SDF's own gradient, taken by central differences two plane voxels
apart, and that normal carries the grain of a field fitted to 16 views at 128 px; the albedo, free
at every point, takes up whatever shading that grain puts on the photos, and comes back grainy
(the mug's glaze a speckled red). An L1 difference between each surface point's albedo and a point a
short random step away penalises grain far more than the edges of a painted pattern (a band or a
dot costs its outline once, noise costs everywhere), so the grain is left to the normal and the
lighting, and the pattern stays.
"""

from __future__ import annotations

import torch


def albedo_difference(field, points: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """(K, 3) surface points and (K, 3) small offsets -> the mean L1 difference (summed over the
    channels) of the field's albedo between each point and the point offset from it."""
    if points.shape[0] == 0:
        return points.new_zeros(())
    both = torch.cat([points, points + offsets])[None]
    albedo = field.sample(both, materials=False).albedo[0]
    here, there = albedo[: points.shape[0]], albedo[points.shape[0]:]
    return (here - there).abs().sum(-1).mean()
