"""The texture fit's reads of its textures (texel_reads.py): grid_sample's bilinear reads, as a sparse matrix."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from lirm.engine.export.texel_reads import TexelReads


def _grid_sample(texture: torch.Tensor, uv: torch.Tensor) -> torch.Tensor:
    return F.grid_sample(texture.permute(2, 0, 1)[None], (uv * 2 - 1)[None, None], mode="bilinear",
                         padding_mode="border", align_corners=False)[0, :, 0].T


@pytest.mark.parametrize("size", [1, 2, 7, 32])
def test_reads_and_their_gradients_are_grid_samples(size):
    g = torch.Generator().manual_seed(size)
    # inside, on texel centres, on the atlas's edges and beyond them (the border texels are read there)
    uv = torch.cat([torch.rand(500, 2, generator=g), (torch.arange(size) + 0.5)[:, None].repeat(1, 2) / size,
                    torch.tensor([[0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [-0.2, 0.5], [1.3, 0.4]])])
    texture = torch.rand(size, size, 5, generator=g)
    weights = torch.rand(uv.shape[0], 5, generator=g)
    ours = texture.clone().requires_grad_(True)
    theirs = texture.clone().requires_grad_(True)
    read, expected = TexelReads(uv, size)(ours), _grid_sample(theirs, uv)
    torch.testing.assert_close(read, expected, atol=1e-6, rtol=1e-5)
    (read * weights).sum().backward()
    (expected * weights).sum().backward()
    torch.testing.assert_close(ours.grad, theirs.grad, atol=1e-5, rtol=1e-5)


def test_a_texture_of_another_size_is_refused():
    reads = TexelReads(torch.rand(10, 2), 8)
    with pytest.raises(ValueError, match="8 x 8 texture, not"):
        reads(torch.rand(16, 16, 3))


def test_pooled_reads_are_the_means_of_each_run_with_their_gradients():
    g = torch.Generator().manual_seed(3)
    uv, texture = torch.rand(40, 2, generator=g), torch.rand(9, 9, 5, generator=g)
    weights = torch.rand(10, 5, generator=g)
    ours, theirs = texture.clone().requires_grad_(True), texture.clone().requires_grad_(True)
    pooled = TexelReads(uv, 9, pooled=4)(ours)
    expected = TexelReads(uv, 9)(theirs).reshape(10, 4, 5).mean(1)
    torch.testing.assert_close(pooled, expected)
    (pooled * weights).sum().backward()
    (expected * weights).sum().backward()
    torch.testing.assert_close(ours.grad, theirs.grad)
    with pytest.raises(ValueError, match="whole runs of 3"):
        TexelReads(uv, 9, pooled=3)
