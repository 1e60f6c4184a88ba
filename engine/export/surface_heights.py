"""Registering the photos through the surface: a height map over the export's atlas, shared by all photos.

The texture fit holds each texel to the photo pixels that see it through the export's surface. Where
that surface is off (lumps and dents a few hundredths of the object's radius, from a few 128 px views),
the texel's true point lies above or below the mesh, and each photo sees it displaced by its own
parallax: the fit averages the displaced copies into a blur. A smooth warp per photo
(photo_registration.ViewWarps) cannot undo that, since the displacement changes with the place on the
surface and with the view together. Here each texel gets one height along the surface's normal, the
same for every photo, and a photo pixel whose surface point is p is read where p + h n projects:
to first order, at its centre moved by h times its parallax (pixels per unit of height, recorded per
pixel when the photos are rasterised). So the heights are a depth correction found by photo
consistency across views, as multi-view stereo finds depth, at the texture fit's resolution.

The heights live on a coarse map over the atlas (bilinear), bounded by a scaled tanh, with a
smoothness term between neighbouring cells and a small pull toward zero. A height map cell near a
chart's border also reaches the neighbouring chart in the atlas (a coarse map's cells straddle the
gutters): the smoothness keeps such bleeding small.

The heights are geometry, not only a registration: on the synthetic set's four refined fields they
moved the export's surface toward the truth on every object (Chamfer distance -3% to -16%; README),
so the export's vertices are moved by them too (`displaced`), and each output view then sees each
texel where the photos saw it. The vertex normals and the normal map stay: the fit shaded with them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch
import torch.nn.functional as F

from .photo_registration import PhotoSources
from .uv_atlas import UVMesh


class SurfaceHeights(torch.nn.Module):
    """A `size` x `size` height map over the atlas, each height within `max_height` (field units),
    read at each photo pixel's texture coordinates `pixel_uv` (N, 2)."""

    def __init__(self, size: int, max_height: float, pixel_uv: torch.Tensor):
        super().__init__()
        if size < 2:
            raise ValueError(f"a height map needs at least 2 x 2 cells, got {size}")
        if not max_height > 0:
            raise ValueError(f"the heights' bound must be positive, got {max_height}")
        self.size, self.max_height = size, float(max_height)
        self.raw = torch.nn.Parameter(torch.zeros(1, 1, size, size))
        self.register_buffer("where", (pixel_uv * 2 - 1)[None, None].contiguous())  # glTF uv -> grid_sample's

    def cells(self) -> torch.Tensor:
        """(1, 1, S, S) heights, each within max_height."""
        return self.max_height * torch.tanh(self.raw / self.max_height)

    def heights(self) -> torch.Tensor:
        """(N,) the height at each pixel's texel."""
        return F.grid_sample(self.cells(), self.where, mode="bilinear", padding_mode="border", align_corners=False)[0, 0, 0]

    def offsets(self, sources: PhotoSources) -> torch.Tensor:
        """(N, 2) where each pixel's texel shows in its photo, relative to the pixel's centre (pixels)."""
        if sources.parallax is None:
            raise ValueError("registering through the surface needs each pixel's parallax "
                             "(sample_photo_pixels records it with with_sources=True)")
        return self.heights()[:, None] * sources.parallax

    def smoothness(self) -> torch.Tensor:
        """Mean squared difference between neighbouring cells, in units of max_height squared."""
        cells = self.cells()[0, 0] / self.max_height
        return ((cells[1:] - cells[:-1]) ** 2).mean() + ((cells[:, 1:] - cells[:, :-1]) ** 2).mean()

    def magnitude(self) -> torch.Tensor:
        """Mean squared height (units of max_height squared): of heights that agree equally, the smallest."""
        return ((self.cells() / self.max_height) ** 2).mean()

    def mean_shift(self, sources: PhotoSources) -> float:
        with torch.no_grad():
            return float(self.offsets(sources).norm(dim=-1).mean())

    def mean_height(self) -> float:
        """The mean absolute height over the pixels (field units)."""
        with torch.no_grad():
            return float(self.heights().abs().mean())


def displaced(mesh: UVMesh, heights: np.ndarray) -> UVMesh:
    """`mesh` with each vertex moved along its normal by the height map `heights` (S, S; field units)
    read bilinearly at its texture coordinates; normals, tangents and coordinates unchanged. A vertex
    on a seam between charts is one point with a texture coordinate in each: its copies all move by
    their mean height, so that the seam stays closed."""
    cells = torch.from_numpy(np.asarray(heights, np.float32))[None, None]
    where = torch.from_numpy(np.asarray(mesh.uvs, np.float32) * 2 - 1)[None, None]
    lift = F.grid_sample(cells, where, mode="bilinear", padding_mode="border", align_corners=False)[0, 0, 0].numpy()
    _, point, copies = np.unique(mesh.positions, axis=0, return_inverse=True, return_counts=True)
    point = point.reshape(-1)
    lift = (np.bincount(point, weights=lift, minlength=len(copies)) / copies)[point]
    return replace(mesh, positions=(mesh.positions + lift[:, None] * mesh.normals).astype(np.float32))
