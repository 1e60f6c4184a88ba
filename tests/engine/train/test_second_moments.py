"""AdamW's second moments in 8 bits beside a slim checkpoint: the round trip keeps sqrt(v) within the
quantisation's ±4.4% and exact zeros, and the companion's name follows the slim copy's."""

from pathlib import Path

import torch

from lirm.engine.train.second_moments import dequantize_log2, quantize_log2, second_moments_path


def test_log2_codes_keep_the_square_root_within_five_percent_and_zeros_exact():
    generator = torch.Generator().manual_seed(0)
    v = torch.exp2(torch.empty(10_000).uniform_(-66.0, -6.0, generator=generator))  # squared gradients, 20 decades
    v[::7] = 0.0
    codes, bounds = quantize_log2(v)
    assert codes.dtype == torch.uint8 and codes.shape == v.shape
    back = dequantize_log2(codes, bounds)
    positive = v > 0
    assert torch.equal(back[~positive], torch.zeros_like(back[~positive]))
    ratio = (back[positive] / v[positive]).sqrt()
    assert float((ratio - 1).abs().max()) < 0.045
    assert float(back[positive].min()) > 0


def test_an_all_zero_tensor_and_a_constant_one_survive():
    codes, bounds = quantize_log2(torch.zeros(5))
    assert torch.equal(dequantize_log2(codes, bounds), torch.zeros(5))
    constant = torch.full((4,), 3e-9)
    codes, bounds = quantize_log2(constant)
    torch.testing.assert_close(dequantize_log2(codes, bounds), constant, rtol=1e-5, atol=0)


def test_the_companion_is_named_after_the_slim_copy():
    assert second_moments_path(Path("a/lirm-small-resume.safetensors")) == Path("a/lirm-small-resume.adam-v.safetensors")
