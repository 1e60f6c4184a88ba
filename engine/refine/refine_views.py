"""The views a refinement fits: every pixel's ray, masked colour and mask, flattened for sampling.

Built from a capture's prepared views (their crops at full prepared size, each pixel on the ray it
had in the photo) or from rendered views (evaluation). Rays along the mask's edge are listed apart,
so that a share of every batch can be drawn there: the silhouette is where the shape is decided.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from lirm.engine.cameras import Camera
from lirm.engine.errors import LirmUserError


@dataclass
class RefineViews:
    names: list[str]
    cameras: list[Camera]
    images: np.ndarray  # (V, H, W, 3) display sRGB, the object on white
    masks: np.ndarray  # (V, H, W) in [0, 1]
    origins: torch.Tensor  # (V*H*W, 3)
    directions: torch.Tensor  # (V*H*W, 3) unit
    colours: torch.Tensor  # (V*H*W, 3)
    alphas: torch.Tensor  # (V*H*W,)
    edge_index: torch.Tensor  # flat indices of the pixels within 2 px of a mask edge
    pixel_angles: torch.Tensor  # (V*H*W,) the angle one pixel spans (1 / focal length): its footprint over distance
    # Flat indices the uniform share of a batch is drawn from (None: every pixel): `through_grid`.
    uniform_index: torch.Tensor | None = None

    @property
    def count(self) -> int:
        return len(self.cameras)

    @property
    def pixels(self) -> int:
        return int(self.alphas.shape[0])

    @classmethod
    def build(cls, names: list[str], cameras: list[Camera], images: np.ndarray, masks: np.ndarray) -> "RefineViews":
        if not len(cameras):
            raise LirmUserError("refinement needs at least one view with a camera, image and mask")
        images = np.ascontiguousarray(images, dtype=np.float32)
        masks = np.ascontiguousarray(masks, dtype=np.float32)
        if not np.isfinite(images).all() or not np.isfinite(masks).all():
            raise LirmUserError("the views hold NaN or infinite pixels; re-prepare the capture (lirm capture --resume)")
        images, masks = np.clip(images, 0.0, 1.0), np.clip(masks, 0.0, 1.0)
        origins, directions, edges, angles = [], [], [], []
        offset = 0
        for camera, mask in zip(cameras, masks):
            o, d = camera.pixel_rays()
            origins.append(o.reshape(-1, 3))
            angles.append(np.full(mask.size, 1.0 / np.sqrt(camera.fx * camera.fy)))
            directions.append(d.reshape(-1, 3))
            binary = (mask > 0.5).astype(np.uint8)
            kernel = np.ones((5, 5), np.uint8)
            edge = cv2.dilate(binary, kernel) != cv2.erode(binary, kernel)
            edges.append(np.flatnonzero(edge.ravel()) + offset)
            offset += mask.size
        as_tensor = lambda a: torch.from_numpy(np.ascontiguousarray(np.concatenate(a), dtype=np.float32))  # noqa: E731
        return cls(list(names), list(cameras), images, masks, as_tensor(origins), as_tensor(directions),
                   torch.from_numpy(images.reshape(-1, 3).copy()), torch.from_numpy(masks.reshape(-1).copy()),
                   torch.from_numpy(np.concatenate(edges).astype(np.int64)), as_tensor(angles))

    @classmethod
    def from_prepared(cls, views: list) -> "RefineViews":
        """A capture's PreparedViews (capture/crop.py) at their prepared size."""
        return cls.build([v.frame_id for v in views], [v.camera for v in views],
                         np.stack([v.image_masked for v in views]), np.stack([v.mask for v in views]))

    @classmethod
    def from_object_views(cls, views, names: list[str] | None = None) -> "RefineViews":
        """Rendered views (synth/object_views.py ObjectViews), e.g. a held-out object's input crops."""
        names = names or [f"view_{i:02d}" for i in range(len(views.cameras))]
        return cls.build(names, list(views.cameras), views.image, views.mask)

    def select(self, indices: list[int]) -> "RefineViews":
        return RefineViews.build([self.names[i] for i in indices], [self.cameras[i] for i in indices],
                                 self.images[indices], self.masks[indices])

    def through_grid(self, grid, radius: float) -> "RefineViews":
        """These views with the uniform share of every batch drawn only from pixels whose ray meets
        the occupancy grid (the masks' dilated hull): the others render empty whatever the field is,
        and would spend the batch on nothing (most of a whole frame's pixels round a small object)."""
        from .ray_rendering import rays_meeting_grid

        meets = rays_meeting_grid(self.origins, self.directions, grid, radius)
        if not bool(meets.any()):
            return self
        return dataclasses.replace(self, uniform_index=meets.nonzero(as_tuple=True)[0])

    def sample_rays(self, count: int, edge_fraction: float, generator: torch.Generator) -> torch.Tensor:
        """Flat pixel indices of one batch: uniform over every pixel (or over `uniform_index`), plus
        `edge_fraction` from the edges."""
        edges = int(round(count * edge_fraction)) if len(self.edge_index) else 0
        if self.uniform_index is not None:
            uniform = self.uniform_index[torch.randint(0, len(self.uniform_index), (count - edges,), generator=generator)]
        else:
            uniform = torch.randint(0, self.pixels, (count - edges,), generator=generator)
        if not edges:
            return uniform
        pick = torch.randint(0, len(self.edge_index), (edges,), generator=generator)
        return torch.cat([uniform, self.edge_index[pick]])

    def neighbours(self, index: torch.Tensor, radius_px: int, generator: torch.Generator) -> torch.Tensor:
        """For each flat pixel index, another pixel of the same view at most `radius_px` away in x and
        y (never itself; kept inside the image): pairs of nearby rays for the albedo smoothness term."""
        _, height, width = self.masks.shape
        per_view = height * width
        view, rest = index // per_view, index % per_view
        y, x = rest // width, rest % width
        span = 2 * radius_px + 1
        offset = torch.randint(0, span * span - 1, index.shape, generator=generator)
        offset = offset + (offset >= (span * span) // 2).long()  # skip the centre: (0, 0)
        dy, dx = offset // span - radius_px, offset % span - radius_px
        y2 = (y + dy).clamp(0, height - 1)
        x2 = (x + dx).clamp(0, width - 1)
        return view * per_view + y2 * width + x2
