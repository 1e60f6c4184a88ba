"""Registering the photos to the export before its textures are fitted: a smooth 2D warp per photo.

The texture fit holds each texel to the photo pixels that see it, through the export's surface. Where
that surface is off by a little (a few 128 px views leave the reconstruction a pixel or two from the
object here and there), each photo sees a texel's detail displaced by its own parallax, and the fit
averages the displaced copies into a blur: on the synthetic set the fitted albedo's fine detail had
most of the truth's energy but correlated with it at only about 0.5 (README, "the swap study"). As
in colour-map optimisation for scanned meshes (Zhou and Koltun 2014: per-image deformation grids
fitted jointly with the texture), each photo here gets a coarse grid of pixel offsets, bilinearly
interpolated over the image, and where a pixel samples its photo moves by them; the offsets are
fitted together with the textures to the same photometric error, so every photo is moved toward
the texture all of them agree on. A smoothness term between neighbouring grid nodes and a bound on
the shift (a scaled tanh) keep the warp from explaining texture by bending the photo, and a small
pull toward zero picks, of the warps that agree equally well, the smallest: moving every photo the
same way would slide the texture over the surface without changing any photo's error.

What this leaves the fit is each pixel's colour read at its registered position; the mesh, its
cameras and the photos themselves are not changed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F


@dataclass
class PhotoSources:
    """Where each of the texture fit's N photo pixels comes from, so that it can be read again elsewhere."""

    xy: torch.Tensor  # (N, 2) the pixel's centre in its photo, in pixels (x right, y down; centre of (0, 0) at 0.5)
    view: torch.Tensor  # (N,) int64: which photo
    images: torch.Tensor  # (V, H, W, 3) the photos' display sRGB
    masks: torch.Tensor  # (V, H, W) the photos' object masks
    # (N, 2) how far (pixels) the pixel's surface point moves in its photo per unit it is raised along
    # the surface's normal (surface_heights.py; None: not recorded)
    parallax: torch.Tensor | None = None

    def subset(self, keep: torch.Tensor) -> "PhotoSources":
        return PhotoSources(self.xy[keep], self.view[keep], self.images, self.masks,
                            None if self.parallax is None else self.parallax[keep])

    @property
    def views(self) -> int:
        return int(self.images.shape[0])


class ViewWarps(torch.nn.Module):
    """Per photo, a `grid` x `grid` lattice of 2D offsets (pixels) spanning the image, bilinear between
    nodes. The lattices of all photos sit side by side in one tensor: each photo's nodes are addressed
    with align_corners=True, so interpolation never blends one photo's nodes with the next's."""

    def __init__(self, views: int, grid: int, max_shift: float):
        super().__init__()
        if grid < 2:
            raise ValueError(f"a warp lattice needs at least 2 x 2 nodes, got {grid}")
        self.views, self.grid, self.max_shift = views, grid, float(max_shift)
        self.raw = torch.nn.Parameter(torch.zeros(1, 2, grid, views * grid))

    def nodes(self) -> torch.Tensor:
        """(1, 2, G, V * G) offsets in pixels, each within max_shift."""
        return self.max_shift * torch.tanh(self.raw / self.max_shift)

    def offsets(self, sources: PhotoSources) -> torch.Tensor:
        """(N, 2) the offset at each pixel, in pixels."""
        height, width = sources.images.shape[1:3]
        g, columns = self.grid, self.views * self.grid
        # the pixel's place in its own lattice, in node units, then in the side-by-side tensor
        column = sources.xy[:, 0] / width * (g - 1) + sources.view.to(sources.xy.dtype) * g
        row = sources.xy[:, 1] / height * (g - 1)
        where = torch.stack([column / (columns - 1) * 2 - 1, row / (g - 1) * 2 - 1], -1)
        return F.grid_sample(self.nodes(), where[None, None], mode="bilinear", align_corners=True)[0, :, 0].T

    def smoothness(self) -> torch.Tensor:
        """Mean squared difference between neighbouring nodes of the same photo (pixels²)."""
        nodes = self.nodes().reshape(2, self.grid, self.views, self.grid)
        across = (nodes[..., 1:] - nodes[..., :-1]) ** 2
        down = (nodes[:, 1:] - nodes[:, :-1]) ** 2
        return across.mean() + down.mean()

    def magnitude(self) -> torch.Tensor:
        """Mean squared offset over the nodes (pixels²): a shift that all photos share moves the texture
        on the surface and no photo's error, so this picks the smallest warps that agree."""
        return (self.nodes() ** 2).mean()

    def mean_shift(self, sources: PhotoSources) -> float:
        with torch.no_grad():
            return float(self.offsets(sources).norm(dim=-1).mean())


def read_photos(sources: PhotoSources, offsets: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Each pixel's colour (N, 3) and mask (N,) read bilinearly at its centre moved by `offsets` (N, 2;
    None: not moved). A read stays inside its own photo (clamped half a pixel inside the edges)."""
    views, height, width = sources.images.shape[:3]
    stacked = torch.cat([sources.images, sources.masks[..., None]], -1)  # (V, H, W, 4)
    side_by_side = stacked.permute(3, 1, 0, 2).reshape(1, 4, height, views * width)
    xy = sources.xy if offsets is None else sources.xy + offsets
    x = xy[:, 0].clamp(0.5, width - 0.5) + sources.view.to(xy.dtype) * width
    y = xy[:, 1].clamp(0.5, height - 0.5)
    where = torch.stack([x / (views * width) * 2 - 1, y / height * 2 - 1], -1)
    read = F.grid_sample(side_by_side, where[None, None], mode="bilinear", align_corners=False)[0, :, 0].T
    return read[:, :3], read[:, 3]


def photo_sources(pixel_xy: list[np.ndarray], images: np.ndarray, masks: np.ndarray,
                  parallax: list[np.ndarray] | None = None) -> PhotoSources:
    """PhotoSources from each photo's kept pixels' (x, y) centres (a list over the photos), and
    optionally their parallax (a list of (n, 2) arrays, the same order)."""
    xy = np.concatenate(pixel_xy).astype(np.float32) if pixel_xy else np.zeros((0, 2), np.float32)
    view = np.concatenate([np.full(len(p), i, np.int64) for i, p in enumerate(pixel_xy)]) if pixel_xy else np.zeros(0, np.int64)
    moves = None
    if parallax is not None:
        moves = torch.from_numpy(np.concatenate(parallax).astype(np.float32) if parallax else np.zeros((0, 2), np.float32))
    return PhotoSources(torch.from_numpy(xy), torch.from_numpy(view),
                        torch.from_numpy(np.asarray(images, np.float32)), torch.from_numpy(np.asarray(masks, np.float32)), moves)
