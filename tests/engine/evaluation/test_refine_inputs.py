"""The views a held-out object's refinement fits: the frames' own pixels, never resampled."""

from __future__ import annotations

import numpy as np

from lirm.engine.evaluation.heldout_sets import synthetic_heldout
from lirm.engine.evaluation.refined_rows import refine_inputs
from lirm.engine.synth.view_crops import crop_like_capture
from lirm.renderer.context import create_headless_context
from lirm.renderer.pbr_renderer import PBRRenderer


def test_the_refinement_fits_the_held_out_frames_at_their_own_pixels():
    ctx = create_headless_context()
    renderer = PBRRenderer(ctx)
    try:
        obj = synthetic_heldout(renderer, count=1, size=48, surface_points=100)[0]
    finally:
        renderer.release()
        ctx.release()
    indices = list(obj.protocol.input_sets[0])
    views = refine_inputs(obj, indices)
    assert views.count == len(indices)
    for k, i in enumerate(indices):
        camera, frame = views.cameras[k], obj.views.cameras[i]
        assert (camera.width, camera.height) == (frame.width, frame.height)
        assert np.allclose([camera.fx, camera.fy, camera.cx, camera.cy], [frame.fx, frame.fy, frame.cx, frame.cy])
        assert np.array_equal(views.images[k], np.clip(obj.views.image[i], 0.0, 1.0).astype(np.float32))
        assert np.array_equal(views.masks[k], np.clip(obj.views.mask[i], 0.0, 1.0).astype(np.float32))
    # What it replaced: the network's crops resized back to the frame's size are other pixels (the
    # object smaller than the frame is upsampled by interpolation), so this test tells the two apart.
    crops = crop_like_capture(obj.views.select(indices), obj.views.image.shape[1])
    assert not np.allclose(crops.image, views.images, atol=1e-3)
