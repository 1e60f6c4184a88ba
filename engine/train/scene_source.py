"""Training scenes where training runs: rendered on the fly by the PBR renderer, optionally kept in
a local disk cache so that a pool of scenes is rendered once and reused.

Each process (and each data-loader worker) makes its own headless GL context the first time it
needs one. A scene is rendered at the network's input size and cut like the capture pipeline cuts
photos (synth/view_crops.py); that cropped scene is what the cache holds, keyed by the generator
version, the scene config and the seed. A scene that fails to render (a model that loaded but
breaks the renderer) is reported once and skipped; the caller draws another seed.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import asdict
from pathlib import Path

import numpy as np

from lirm.engine.cameras import Camera
from lirm.engine.io.atomic_files import atomic_write
from lirm.engine.synth.object_views import ObjectViews
from lirm.engine.synth.training_scenes import GENERATOR_VERSION, TrainingSceneConfig, make_training_scene
from lirm.engine.synth.view_crops import crop_like_capture

log = logging.getLogger(__name__)

_MAPS = ("image", "image_bg", "mask", "albedo", "roughness", "metallic", "normal", "depth")


class SceneRenderError(RuntimeError):
    """The renderer failed on a scene; the scene is skipped."""


class SceneSource:
    def __init__(self, config: TrainingSceneConfig, input_size: int, cache_dir: str | Path | None = None):
        self.config = config
        self.input_size = input_size
        self.cache_dir = Path(cache_dir) if cache_dir else None
        self._renderer = None
        self._context = None
        self._environments: dict = {}
        self.failed_seeds: set[int] = set()
        key = json.dumps({"version": GENERATOR_VERSION, "scene": asdict(self.config), "input": input_size}, sort_keys=True)
        self.key = hashlib.sha256(key.encode()).hexdigest()[:12]

    def scene(self, seed: int) -> ObjectViews:
        """The cropped views of scene `seed` (from the cache when it holds them)."""
        cached = self._cache_path(seed)
        if cached is not None and cached.is_file():
            try:
                return _load_views(cached)
            except Exception as err:  # a damaged cache entry is re-rendered, not fatal
                log.warning("scene cache entry %s is unreadable (%s); rendering it again", cached, err)
        # Stored at the cache's precision whether cached or not: a step must see the same data in a
        # run that rendered its scene and in a resumed run that reads it back.
        views = _at_cache_precision(crop_like_capture(self._render(seed), self.input_size))
        if cached is not None:
            atomic_write(cached, lambda tmp: _save_views(tmp, views))
        return views

    def _render(self, seed: int) -> ObjectViews:
        renderer = self._renderer_here()
        try:
            return make_training_scene(renderer, seed, self.config, self._environments).views
        except Exception as err:
            self.failed_seeds.add(seed)
            raise SceneRenderError(f"training scene {seed} failed to render: {type(err).__name__}: {err}") from err

    def _renderer_here(self):
        if self._renderer is None:
            from lirm.renderer.context import create_headless_context
            from lirm.renderer.pbr_renderer import PBRRenderer

            self._context = create_headless_context()
            self._renderer = PBRRenderer(self._context)
        return self._renderer

    def _cache_path(self, seed: int) -> Path | None:
        return None if self.cache_dir is None else self.cache_dir / self.key / f"scene_{seed:010d}.npz"

    def release(self) -> None:
        if self._renderer is not None:
            self._renderer.release()
            self._context.release()
            self._renderer = self._context = None

    def __getstate__(self):  # data-loader workers get a copy without the parent's GL objects
        state = dict(self.__dict__)
        state["_renderer"] = state["_context"] = None
        return state


def _at_cache_precision(views: ObjectViews) -> ObjectViews:
    maps = {name: None if getattr(views, name) is None else getattr(views, name).astype(np.float16).astype(np.float32)
            for name in _MAPS}
    return ObjectViews(views.cameras, **maps)


def _save_views(path: Path, views: ObjectViews) -> None:
    arrays = {name: getattr(views, name).astype(np.float16) for name in _MAPS if getattr(views, name) is not None}
    cameras = json.dumps([c.to_dict() for c in views.cameras])
    with open(path, "wb") as f:
        np.savez_compressed(f, cameras=np.array(cameras), **arrays)


def _load_views(path: Path) -> ObjectViews:
    with np.load(path) as data:
        cameras = [Camera.from_dict(d) for d in json.loads(str(data["cameras"]))]
        maps = {name: data[name].astype(np.float32) if name in data else None for name in _MAPS}
    return ObjectViews(cameras, **maps)
