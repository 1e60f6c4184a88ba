"""Does a reconstructor use its inputs? The prediction at one object's surface from its own first
input set, against the prediction at the same points from another object's first input set.

A model that has only learned a prior (the same blob whatever it is shown) scores about 0; any
model that reads its views scores clearly above it. It is the first thing to check of a checkpoint
trained on little compute: scores can beat trivial baselines by the prior alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .evaluate import model_device, model_inputs
from .heldout_sets import HeldoutObject


@dataclass
class InputSensitivity:
    albedo: float  # mean |albedo difference| (linear RGB) at the surface points, own views vs another object's
    sdf: float  # mean |SDF difference| there, in units of the bounding-sphere radius
    pairs: int


@torch.no_grad()
def input_sensitivity(model, objects: list[HeldoutObject], points: int = 2000) -> InputSensitivity:
    if len(objects) < 2:
        raise ValueError("input sensitivity needs at least two held-out objects")
    device = model_device(model)
    albedo, sdf = [], []
    for k, obj in enumerate(objects):
        other = objects[(k + 1) % len(objects)]
        if obj.surface is None or not len(obj.surface):
            continue
        p = torch.from_numpy(np.ascontiguousarray(obj.surface[:points], np.float32))[None].to(device)
        samples = []
        for source in (obj, other):
            state = model.update(model.initial_state(1), model_inputs(model, source, source.protocol.input_sets[0], device))
            samples.append(model.decode(state).sample(p))
        albedo.append(float((samples[0].albedo - samples[1].albedo).abs().mean()))
        sdf.append(float((samples[0].sdf - samples[1].sdf).abs().mean()))
    if not albedo:
        raise ValueError("input sensitivity needs objects with known surfaces")
    return InputSensitivity(float(np.mean(albedo)), float(np.mean(sdf)), len(albedo))
