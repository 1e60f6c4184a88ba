"""The training objective: recomputing the crops' renders in the backward pass (render_checkpointing)
changes neither the loss, nor the gradients, nor the samples drawn after it."""

from __future__ import annotations

import pytest
import torch

from lirm.engine.model.config import preset
from lirm.engine.model.lirm import LIRM
from lirm.engine.model.volume_renderer import VolumeRenderConfig
from lirm.engine.synth.training_scenes import TrainingSceneConfig
from lirm.engine.train.losses import LossWeights
from lirm.engine.train.objective import TrainingObjective
from lirm.engine.train.perceptual import perceptual_loss
from lirm.engine.train.scene_source import SceneSource
from lirm.engine.train.stages import stage_config
from lirm.engine.train.training_sample import make_sample


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    source = SceneSource(TrainingSceneConfig(views=12, size=64, environment_width=128), 64, tmp_path_factory.mktemp("cache"))
    try:
        yield make_sample(source, stage_config("tiny", 1), 3, 0, 2, data_seed=0, scene_pool=2)
    finally:
        source.release()


def _loss_and_gradients(sample, render_checkpointing: bool):
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).train()
    objective = TrainingObjective(model, LossWeights(), perceptual_loss(False), render_checkpointing=render_checkpointing)
    render = VolumeRenderConfig(samples_per_ray=16, beta=0.1, stratified=True)
    generator = torch.Generator().manual_seed(11)
    loss, terms = objective(sample.inputs, sample.targets, sample.crop, render, None, generator)
    loss.backward()
    gradients = {name: p.grad.clone() for name, p in model.named_parameters() if p.grad is not None}
    return loss.detach(), terms, gradients, torch.rand(4, generator=generator)


def test_recomputed_renders_give_the_same_loss_gradients_and_samples(sample):
    loss, terms, gradients, after = _loss_and_gradients(sample, False)
    loss_c, terms_c, gradients_c, after_c = _loss_and_gradients(sample, True)
    assert torch.allclose(loss, loss_c, rtol=1e-5, atol=1e-7)
    assert terms.keys() == terms_c.keys() and all(abs(terms[k] - terms_c[k]) < 1e-5 for k in terms)
    assert gradients.keys() == gradients_c.keys() and len(gradients) > 10
    for name in gradients:
        assert torch.allclose(gradients[name], gradients_c[name], rtol=1e-4, atol=1e-6), name
    assert torch.equal(after, after_c)  # the generator moved on as far as without recomputation
    # and the samples matter: another generator state gives another loss
    torch.manual_seed(0)
    model = LIRM(preset("tiny")).train()
    objective = TrainingObjective(model, LossWeights(), perceptual_loss(False), render_checkpointing=True)
    other, _ = objective(sample.inputs, sample.targets, sample.crop, VolumeRenderConfig(samples_per_ray=16, beta=0.1, stratified=True),
                         None, torch.Generator().manual_seed(12))
    assert not torch.allclose(loss, other.detach(), rtol=1e-6, atol=0)
