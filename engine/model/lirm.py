"""The LIRM network and its progressive API (paper §3.2, eqs. 6-7 and 12-13).

    state = model.initial_state(batch)           # T^0 = 0, E^0 = 0
    state = model.update(state, views)           # any number of times, 1..k views each
    field = model.decode(state)                  # planes + NDE panoramas + heads

An update sees only the state's tokens and the new views: P^m = MLP_fuse(concat(T^{m-1}, P)) for the
plane tokens (and likewise D^m for the NDE tokens), one transformer over [plane, NDE, image] tokens,
and only the plane and NDE tokens are kept. Memory does not grow with the number of updates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from lirm.engine.errors import LirmUserError

from .config import LIRMConfig
from .field import Field, FieldHeads
from .hexaplane import PlaneDecoder
from .nde import NDEDecoder
from .tokenizer import ImageTokenizer
from .transformer import Transformer


@dataclass
class ReconState:
    plane_tokens: torch.Tensor  # (B, planes * t * t, width)
    nde_tokens: torch.Tensor | None  # (B, t_e * t_e, width)
    updates: int  # how many updates produced it
    signature: str  # LIRMConfig.signature() of the model that made it


@dataclass
class ViewBatch:
    """Prepared views as tensors (capture/crop.py's PreparedView, stacked): images in [0, 1]."""

    image: torch.Tensor  # (B, V, 3, H, W) masked image
    image_bg: torch.Tensor  # (B, V, 3, H, W) background image
    plucker: torch.Tensor  # (B, V, 6, H, W)

    @classmethod
    def from_arrays(cls, images, backgrounds, pluckers, device: torch.device | str = "cpu") -> "ViewBatch":
        """One scene's views from channel-last arrays, (V, H, W, 3), (V, H, W, 3), (V, H, W, 6)."""

        def tensor(a) -> torch.Tensor:
            t = torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).permute(0, 3, 1, 2)  # (V, C, H, W)
            return t.unsqueeze(0).to(device)

        return cls(tensor(images), tensor(backgrounds), tensor(pluckers))


class LIRM(nn.Module):
    def __init__(self, config: LIRMConfig):
        super().__init__()
        self.config = config
        d = config.width
        self.tokenizer = ImageTokenizer(config)
        self.plane_pos = nn.Parameter(torch.randn(1, config.num_plane_tokens, d) * 0.02)
        self.plane_fuse = nn.Sequential(nn.Linear(2 * d, d), nn.GELU(), nn.Linear(d, d))
        if config.colour == "nde":
            self.nde_pos = nn.Parameter(torch.randn(1, config.num_nde_tokens, d) * 0.02)
            self.nde_fuse = nn.Sequential(nn.Linear(2 * d, d), nn.GELU(), nn.Linear(d, d))
            self.nde_decoder = NDEDecoder(config)
        self.transformer = Transformer(d, config.depth, config.heads, config.mlp_ratio)
        self.plane_decoder = PlaneDecoder(config)
        self.heads = FieldHeads(config)

    # ---- the progressive API ------------------------------------------------------------------
    def initial_state(self, batch: int = 1) -> ReconState:
        c = self.config
        device = self.plane_pos.device
        nde = torch.zeros(batch, c.num_nde_tokens, c.width, device=device) if c.colour == "nde" else None
        return ReconState(torch.zeros(batch, c.num_plane_tokens, c.width, device=device), nde, 0, c.signature())

    def update(self, state: ReconState, views: ViewBatch) -> ReconState:
        self._check(state, views)
        c = self.config
        b = state.plane_tokens.shape[0]
        planes_in = self.plane_fuse(torch.cat([state.plane_tokens, self.plane_pos.expand(b, -1, -1)], dim=-1))
        parts = [planes_in]
        if c.colour == "nde":
            parts.append(self.nde_fuse(torch.cat([state.nde_tokens, self.nde_pos.expand(b, -1, -1)], dim=-1)))
        images = self.tokenizer(views.image, views.image_bg, views.plucker)
        out = self.transformer(torch.cat(parts + [images], dim=1))
        n_p, n_e = c.num_plane_tokens, c.num_nde_tokens
        # Only the 3D tokens survive the update; the image tokens (and their activations) are dropped.
        # clone(): a slice would keep the whole output, image tokens included, alive in the state.
        nde = out[:, n_p:n_p + n_e].clone() if n_e else None
        return ReconState(out[:, :n_p].clone(), nde, state.updates + 1, state.signature)

    def decode(self, state: ReconState) -> Field:
        self._check_state(state)
        panoramas = self.nde_decoder(state.nde_tokens) if self.config.colour == "nde" else None
        return Field(self.config, self.heads, self.plane_decoder(state.plane_tokens), panoramas)

    # ---- input checks --------------------------------------------------------------------------------
    def _check_state(self, state: ReconState) -> None:
        if state.signature != self.config.signature():
            raise LirmUserError(
                f"this reconstruction state was made by a different model architecture (signature {state.signature}) "
                f"than the loaded '{self.config.name}' model ({self.config.signature()}); start a new reconstruction"
            )

    def _check(self, state: ReconState, views: ViewBatch) -> None:
        self._check_state(state)
        shapes = {name: tuple(getattr(views, name).shape) for name in ("image", "image_bg", "plucker")}
        image = shapes["image"]
        if len(image) != 5 or image[1] == 0:
            raise LirmUserError(f"an update needs at least one view, shaped (batch, views, channels, H, W); got {image}")
        b, v, _, h, w = image
        expected = {"image": (b, v, 3, h, w), "image_bg": (b, v, 3, h, w), "plucker": (b, v, 6, h, w)}
        for name, shape in shapes.items():
            if shape != expected[name]:
                raise LirmUserError(f"views of mismatched sizes: {name} is {shape}, expected {expected[name]}")
        if h % self.config.patch or w % self.config.patch:
            raise LirmUserError(f"views of {w}x{h} are not a multiple of the {self.config.patch}-pixel patch; re-crop them")
        if b != state.plane_tokens.shape[0]:
            raise LirmUserError(f"the views are a batch of {b} but the state holds {state.plane_tokens.shape[0]}")
        for name in shapes:
            if not torch.isfinite(getattr(views, name)).all():
                raise LirmUserError(f"the views' {name} contains NaN or infinite values; re-prepare the capture")
