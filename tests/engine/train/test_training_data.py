"""Training data: the scene cache, and samples that depend only on (data seed, step, rank)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lirm.engine.synth.training_scenes import TrainingSceneConfig
from lirm.engine.train.scene_source import SceneSource
from lirm.engine.train.stages import stage_config
from lirm.engine.train.training_sample import make_sample

SCENES = TrainingSceneConfig(views=16, size=64, environment_width=128)


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    s = SceneSource(SCENES, 64, tmp_path_factory.mktemp("cache"))
    yield s
    s.release()


def test_cached_scene_equals_the_rendered_one_and_a_damaged_entry_is_rendered_again(source):
    rendered = source.scene(5)
    entry = source._cache_path(5)
    assert entry.is_file()
    cached = source.scene(5)
    # Fresh renders are kept at the cache's precision, so both are the same data.
    np.testing.assert_array_equal(cached.image, rendered.image)
    np.testing.assert_array_equal(cached.normal, rendered.normal)
    np.testing.assert_allclose(cached.cameras[3].plucker(), rendered.cameras[3].plucker(), atol=1e-6)
    entry.write_bytes(b"damaged")
    again = source.scene(5)
    np.testing.assert_allclose(again.image, rendered.image, atol=1e-3)


def test_a_step_sample_depends_only_on_seed_step_and_rank(source):
    stage = stage_config("tiny", 1)
    a = make_sample(source, stage, 7, 0, 2, data_seed=1, scene_pool=2)
    b = make_sample(source, stage, 7, 0, 2, data_seed=1, scene_pool=2)
    c = make_sample(source, stage, 7, 1, 2, data_seed=1, scene_pool=2)
    assert a.scene_seeds == b.scene_seeds
    for u in range(stage.update_sets):
        for x, y in zip(a.inputs[u], b.inputs[u]):
            assert torch.equal(x, y)
        assert torch.equal(a.targets[u][0]["colour"], b.targets[u][0]["colour"])
    def same(s1, s2) -> bool:
        return s1.scene_seeds == s2.scene_seeds and all(x.shape == y.shape and torch.equal(x, y) for x, y in zip(s1.inputs[0], s2.inputs[0]))

    assert same(a, b) and not same(a, c)  # another process gets other data
    # Shapes: update sets of 3-6 views at the model's input size; target crops of the stage's size.
    image, background, plucker = a.inputs[0]
    assert image.shape[0] == 2 and 3 <= image.shape[1] <= 6 and image.shape[-2:] == (64, 64)
    assert plucker.shape[2] == 6 and background.shape == image.shape
    t = a.targets[0][0]
    assert t["origins"].shape == (stage.targets_per_update * stage.crop**2, 3) and t["mask"].shape == (stage.targets_per_update * stage.crop**2,)
    assert torch.allclose(t["directions"].norm(dim=-1), torch.ones(1), atol=1e-5)
