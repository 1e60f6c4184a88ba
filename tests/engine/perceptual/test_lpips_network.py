"""LPIPS with the real weights (fetched by `make setup`): what a perceptual distance must do on a
real photo. Skipped, with the reason, on a machine where the weights could not be fetched."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from lirm.engine.perceptual.lpips_network import load_lpips
from lirm.engine.perceptual.lpips_weights import missing_weights_reason


@pytest.fixture(scope="module", params=["alex", "vgg"])
def lpips_net(request):
    why = missing_weights_reason(request.param)
    if why:
        pytest.skip(why)
    return load_lpips(request.param)


@pytest.fixture(scope="module")
def photo(shared_data) -> torch.Tensor:
    path = sorted((shared_data / "real_instantngp_fox" / "images").iterdir())[0]
    image = cv2.resize(cv2.imread(str(path))[:, :, ::-1], (128, 128), interpolation=cv2.INTER_AREA)
    return torch.from_numpy(image.astype(np.float32) / 255.0).permute(2, 0, 1)[None]


def _blurred(image: torch.Tensor, sigma: float) -> torch.Tensor:
    hwc = image[0].permute(1, 2, 0).numpy()
    return torch.from_numpy(cv2.GaussianBlur(hwc, (0, 0), sigma)).permute(2, 0, 1)[None]


def test_zero_for_the_same_image_symmetric_and_growing_with_the_damage(lpips_net, photo):
    with torch.no_grad():
        assert float(lpips_net(photo, photo)) == pytest.approx(0.0, abs=1e-6)
        blurred = [_blurred(photo, s) for s in (0.7, 1.5, 3.0)]
        distances = [float(lpips_net(photo, b)) for b in blurred]
        assert 0.0 < distances[0] < distances[1] < distances[2]
        assert float(lpips_net(blurred[1], photo)) == pytest.approx(distances[1], rel=1e-5)
        flat = torch.full_like(photo, float(photo.mean()))
        assert float(lpips_net(photo, flat)) > distances[2]  # all structure gone is worse than a blur


def test_each_image_of_a_batch_is_scored_alone(lpips_net, photo):
    other = _blurred(photo, 2.0)
    with torch.no_grad():
        alone = float(lpips_net(photo, other))
        batch = lpips_net(torch.cat([photo, photo]), torch.cat([other, photo]))
    assert batch.shape == (2,)
    assert float(batch[0]) == pytest.approx(alone, rel=1e-5) and float(batch[1]) == pytest.approx(0.0, abs=1e-6)


def test_differentiable_and_small_images_are_enlarged_not_refused(lpips_net, photo):
    small = torch.nn.functional.interpolate(photo, size=(16, 16), mode="area")
    target = _blurred(small, 1.0)
    x = small.clone().requires_grad_(True)
    lpips_net(x, target).sum().backward()
    assert torch.isfinite(x.grad).all() and x.grad.abs().sum() > 0
    assert all(not p.requires_grad for p in lpips_net.parameters())


def test_image_distance_scores_one_picture_pair_as_the_batch_call_does(lpips_net, photo):
    other = _blurred(photo, 1.5)
    with torch.no_grad():
        expected = float(lpips_net(photo, other))
    as_image = lambda t: t[0].permute(1, 2, 0).numpy().astype(np.float64)  # noqa: E731  what the metrics hold
    assert lpips_net.image_distance(as_image(photo), as_image(other)) == pytest.approx(expected, rel=1e-5)
    assert lpips_net.image_distance(as_image(photo), as_image(photo)) == pytest.approx(0.0, abs=1e-6)
