"""Shared by the refinement tests: the views a refinement fits, rendered from an analytic field."""

from __future__ import annotations

import numpy as np
import pytest

from lirm.engine.model.volume_renderer import VolumeRenderConfig, render_camera
from lirm.engine.refine.refine_views import RefineViews


@pytest.fixture(scope="session")
def analytic_views():
    """(field, cameras) -> RefineViews: each camera's image and mask rendered from the analytic field."""
    def build(truth, cameras) -> RefineViews:
        images, masks = [], []
        for camera in cameras:
            out = render_camera(truth, camera, VolumeRenderConfig(samples_per_ray=128, numerical_normals=False))
            images.append(np.clip(out["colour"], 0, 1))
            masks.append(out["opacity"])
        return RefineViews.build([f"v{i}" for i in range(len(cameras))], cameras, np.stack(images), np.stack(masks))

    return build
