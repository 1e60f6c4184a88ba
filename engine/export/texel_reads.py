"""Bilinear reads of a texture at fixed texture coordinates, as a sparse matrix: the texture fit's lookup.

The texture fit reads its albedo, roughness and metallic textures at the same photo pixels' texture
coordinates on every step; only the texels change. `F.grid_sample` recomputes each read's four
texels and weights every time, forward and backward, and its backward scatters the gradient one read
at a time: on the demo's 1.2M sub-samples its three reads were a fifth of a step. Here the four
texels and weights of each read are found once and held as a sparse matrix A (reads x texels, four
entries a row), so a step's reads are A @ texels and their gradient A^T @ gradient, both held in
compressed rows, for all channels at once.

The reads are `F.grid_sample`'s with `padding_mode="border"` and `align_corners=False` at grid
coordinates uv * 2 - 1 (the glTF convention the fit uses: row 0 is v near 0); a test holds the two
equal, values and gradients.
"""

from __future__ import annotations

import warnings

import torch


class TexelReads:
    """Reads of an `size` x `size` texture at (N, 2) texture coordinates `uv`."""

    def __init__(self, uv: torch.Tensor, size: int, pooled: int = 1):
        """`pooled` > 1: each run of that many consecutive coordinates is one read, their mean (a photo
        pixel's footprint read as one box-filtered sample)."""
        if size < 1:
            raise ValueError(f"a texture needs at least one texel, got size {size}")
        if pooled < 1 or uv.shape[0] % pooled:
            raise ValueError(f"{uv.shape[0]} coordinates do not make whole runs of {pooled}")
        self.size = int(size)
        self.count = int(uv.shape[0]) // pooled
        # grid_sample's unnormalised coordinates (align_corners=False), clamped to the border texels
        x = (uv[:, 0].double() * size - 0.5).clamp(0.0, size - 1.0)
        y = (uv[:, 1].double() * size - 0.5).clamp(0.0, size - 1.0)
        x0, y0 = x.floor(), y.floor()
        fx, fy = x - x0, y - y0
        x0, y0 = x0.long(), y0.long()
        x1, y1 = (x0 + 1).clamp(max=size - 1), (y0 + 1).clamp(max=size - 1)
        texels = torch.stack([y0 * size + x0, y0 * size + x1, y1 * size + x0, y1 * size + x1], 1).reshape(-1)
        weights = torch.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1).reshape(-1).float() / pooled
        reads = torch.arange(self.count).repeat_interleave(4 * pooled)  # (coalescing sums a run's shared texels)
        shape = (self.count, size * size)
        with warnings.catch_warnings():  # torch calls its compressed-row tensors beta; these two use only the product
            warnings.simplefilter("ignore", UserWarning)
            self.matrix = torch.sparse_coo_tensor(torch.stack([reads, texels]), weights, shape,
                                                  check_invariants=False).coalesce().to_sparse_csr()
            self.transposed = torch.sparse_coo_tensor(torch.stack([texels, reads]), weights, shape[::-1],
                                                      check_invariants=False).coalesce().to_sparse_csr()

    def __call__(self, texture: torch.Tensor) -> torch.Tensor:
        """(N, C): the (S, S, C) texture read at the coordinates; differentiable in the texture."""
        if tuple(texture.shape[:2]) != (self.size, self.size):
            raise ValueError(f"these reads are of a {self.size} x {self.size} texture, not {tuple(texture.shape[:2])}")
        return _SparseReads.apply(texture.reshape(self.size * self.size, -1), self.matrix, self.transposed)


class _SparseReads(torch.autograd.Function):
    @staticmethod
    def forward(ctx, texels: torch.Tensor, matrix: torch.Tensor, transposed: torch.Tensor) -> torch.Tensor:
        ctx.transposed = transposed
        return matrix @ texels.contiguous()

    @staticmethod
    def backward(ctx, gradient: torch.Tensor):
        return ctx.transposed @ gradient.contiguous(), None, None
