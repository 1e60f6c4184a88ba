"""Training the image-space material network: it learns a material the photos show, and stops when cancelled."""

from __future__ import annotations

import numpy as np

from lirm.engine.model.material_net import PRESETS, predict_materials
from lirm.engine.train.material_net_training import MaterialData, MaterialTrainingConfig, train_material_net


def _photos(count: int, size: int) -> tuple[np.ndarray, np.ndarray]:
    masks = np.zeros((count, size, size), np.float32)
    masks[:, size // 4: 3 * size // 4, size // 4: 3 * size // 4] = 1.0
    return np.where(masks[..., None] > 0, 0.5, 1.0).astype(np.float32) * np.ones(3, np.float32), masks


def test_training_learns_which_paint_is_metal():
    """Red squares are metal and blue ones paint: a short training must tell them apart."""
    rng = np.random.default_rng(2)
    count, size = 24, 32
    images, masks = _photos(count, size)
    red = rng.uniform(size=count) < 0.5
    colour = np.where(red[:, None], [0.8, 0.1, 0.1], [0.1, 0.1, 0.8]).astype(np.float32)
    images = np.where(masks[..., None] > 0, colour[:, None, None, :], 1.0).astype(np.float32)
    metallic = masks * red[:, None, None]
    data = MaterialData(images, masks, np.where(masks[..., None] > 0, colour[:, None, None, :], 0.0).astype(np.float32),
                        np.full_like(masks, 0.5), metallic.astype(np.float32))
    config = MaterialTrainingConfig(steps=60, batch=6, learning_rate=5e-3)
    net, history = train_material_net(data, config, PRESETS["small"])
    assert len(history) == 60 and history[-1]["metallic"] < 0.5 * history[0]["metallic"]
    maps = predict_materials(net, images, masks)
    inside = masks > 0.5
    assert maps.metallic[red][inside[red]].mean() > 0.7
    assert maps.metallic[~red][inside[~red]].mean() < 0.3


def test_training_stops_when_cancelled():
    images, masks = _photos(4, 32)
    data = MaterialData(images, masks, np.zeros_like(images), np.zeros_like(masks), np.zeros_like(masks))
    calls = {"n": 0}

    def cancelled() -> bool:
        calls["n"] += 1
        return calls["n"] > 3

    _, history = train_material_net(data, MaterialTrainingConfig(steps=50, batch=2), PRESETS["small"], cancelled=cancelled)
    assert len(history) == 3


def test_the_command_renders_trains_saves_and_reuses_its_views(tmp_path, capsys):
    from lirm.engine.cli import main
    from lirm.engine.model.material_net import load_material_net

    out, data = tmp_path / "net.safetensors", tmp_path / "views.npz"
    args = ["train-materials", "--scenes", "2", "--varied-scenes", "1", "--steps", "20", "--preset", "small", "--eval-objects", "0",
            "--data", str(data)]
    assert main(args + ["--out", str(out)]) == 0
    assert "rendered 3/3 scenes" in capsys.readouterr().out and data.is_file()
    net, meta = load_material_net(out)
    assert meta["steps_done"] == 20 and meta["views"] == 24 and meta["preset"] == "small"
    assert meta["training"]["scenes"] == 2 and meta["training"]["varied_scenes"] == 1
    assert main(args + ["--out", str(tmp_path / "again.safetensors")]) == 0
    assert f"reading the rendered views from {data}" in capsys.readouterr().out
    assert main(["train-materials", "--out", str(tmp_path / "net.pt")]) == 2
    assert main(["train-materials", "--scenes", "0", "--varied-scenes", "0"]) == 2 and "nothing to train on" in capsys.readouterr().err
    assert main(["train-materials", "--steps", "3"]) == 2 and "--steps must be between 20" in capsys.readouterr().err
    assert main(["train-materials", "--eval-only", str(tmp_path / "missing.safetensors")]) == 3
    assert "missing.safetensors" in capsys.readouterr().err


def test_the_default_out_is_the_installed_package_checkpoint_that_refine_reads():
    from lirm.engine.commands.train_materials import default_out
    from lirm.engine.refine.image_materials import shipped_material_net

    assert default_out().is_absolute() and default_out() == shipped_material_net()


def test_eval_only_scores_the_shipped_network_on_gltf_models(tmp_path, shared_data, capsys):
    """`--eval-set gltf` scores the network on objects unlike its training's, the check that keeps it an option."""
    from lirm.engine.cli import main
    from lirm.engine.refine.image_materials import shipped_material_net

    models, environments = tmp_path / "models", tmp_path / "environments"
    models.mkdir()
    environments.mkdir()
    (models / "bunny.glb").symlink_to(shared_data / "pbr_models" / "pmndrs_bunny_untextured.glb")
    (environments / "forest.hdr").symlink_to(shared_data / "envmaps" / "forest_slope_1k.hdr")
    assert main(["train-materials", "--eval-only", str(shipped_material_net()), "--eval-set", "gltf",
                 "--models", str(models), "--environments", str(environments)]) == 0
    out = capsys.readouterr().out
    assert "the glTF set's models' 16 input views" in out
    row = next(line for line in out.splitlines() if line.startswith("| bunny |"))
    metallic, none = (float(x) for x in row.split("|")[2:4])
    # The bunny has no metal at all: 'none' is perfect, and the network's guess is finite and below it.
    assert none == float("inf") and 0.0 < metallic < 60.0
    assert main(["train-materials", "--eval-only", str(shipped_material_net()), "--eval-set", "gltf",
                 "--models", str(tmp_path / "nowhere")]) != 0
    assert "nowhere" in capsys.readouterr().err
