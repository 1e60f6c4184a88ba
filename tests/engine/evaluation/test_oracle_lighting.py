"""The bench's oracle lighting (`lirm bench refine --lighting truth`): the inputs' true environment,
in the frame, rotation and exposure they were rendered with."""

from __future__ import annotations

import numpy as np
import torch

from lirm.engine.evaluation.heldout_sets import synthetic_heldout
from lirm.engine.evaluation.refined_rows import oracle_lighting
from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.split_sum_shading import shade
from lirm.renderer.context import create_headless_context
from lirm.renderer.pbr_renderer import PBRRenderer


def test_the_true_g_buffer_under_the_oracle_lighting_reproduces_the_input_photo():
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        obj = synthetic_heldout(renderer, count=1, size=64, surface_points=100)[0]
        lighting = oracle_lighting(obj, renderer)
    finally:
        renderer.release()
        ctx.release()
    views = obj.views
    for i in obj.protocol.input_sets[0][:2]:
        inside = views.mask[i] > 0.999
        _, directions = views.cameras[i].pixel_rays()
        t = lambda a: torch.from_numpy(np.ascontiguousarray(a[inside])).float()  # noqa: E731
        with torch.no_grad():
            radiance = shade(lighting, t(views.albedo[i]), t(views.roughness[i]), t(views.metallic[i]), t(views.normal[i]),
                             -t(directions.reshape(views.mask[i].shape + (3,)))).radiance
            display = radiance_to_display_torch(radiance).numpy()
        error = np.abs(display - views.image[i][inside])
        # Texture filtering and the 2x supersampling differ at texel edges; the light itself must agree.
        assert np.median(error) < 0.015 and error.mean() < 0.03, (np.median(error), error.mean())
        assert abs(display.mean() - views.image[i][inside].mean()) < 0.02
