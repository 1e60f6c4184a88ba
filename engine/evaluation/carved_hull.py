"""A progressive reconstructor without learning whose quality follows the views it is given: the
visual hull of every mask seen so far, coloured from the photos that see each part of it.

Why it exists: the trajectory study (guidance/trajectory_study.py) asks whether choosing the next
views well reconstructs better. The shipped CPU-trained LIRM hardly depends on which views it gets
(its quality after update 3 does not correlate with the coverage of the views chosen), so with it no
choice of views can win beyond noise. This reconstructor gives the study a second subject whose
shape and colour come only from the pixels, so that a better choice of views must show.

It takes exactly what LIRM takes (masked image, background and Plücker rays per view, one set per
update; each view's pinhole camera is recovered from its rays) and keeps constant memory across
updates (a voxel grid and colour sums, no images):
- shape: each view carves away the voxels it sees on background (carving commutes, so after any
  number of updates this is the visual hull of all views so far);
- colour: every view adds its pixel colours, weighted by how squarely it sees the surface (none past
  60 degrees, the coverage rule), to the occupied voxels just below the hull's visible surface;
  voxels no view coloured take the colour of the nearest one that was;
- material: a plain dielectric (roughness 0.5, metallic 0), as the sphere baseline; the albedo is the
  linearised observed colour.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

from lirm.engine.cameras import Camera, camera_from_plucker
from lirm.engine.capture.visual_hull import VOXEL_HALF_DIAGONAL, VoxelHull, distance_to
from lirm.engine.model.field import FieldSample
from lirm.engine.model.lirm import ViewBatch
from lirm.renderer.tonemap import srgb_to_linear

from .baselines import BASELINE_METALLIC, BASELINE_ROUGHNESS, SAME_PIXEL, WHITE, SphereField


@dataclass(frozen=True)
class CarvedHullConfig:
    image_size: int  # the side of the input views it is handed, as LIRM's config says
    name: str = "carved hull"
    radius: float = 1.0  # the cube [-radius, radius]^3 it carves, LIRM's domain
    resolution: int = 64
    max_angle_deg: float = 60.0  # a view colours the surface it sees within this angle of the normal
    colour_depth_voxels: float = 2.5  # and the voxels this far below it (later carving exposes them)


@dataclass
class CarvedHullState:
    occupancy: np.ndarray | None  # (R, R, R) bool; None before any view
    colour_sum: np.ndarray  # (R, R, R, 3) weighted sRGB
    weight: np.ndarray  # (R, R, R)
    updates: int = 0


def object_mask(image: np.ndarray, background: np.ndarray) -> np.ndarray:
    """uint8 mask (255 = object) of a masked input: background pixels are the white fill where the
    background image is not white. Conservative: a pixel that could be either counts as object, so
    carving never removes what might be there."""
    fill = (np.abs(image - background).max(axis=-1) >= SAME_PIXEL) & (image.min(axis=-1) >= WHITE)
    return np.where(fill, 0, 255).astype(np.uint8)


class CarvedHull:
    """The visual hull, coloured from the photos: the trajectory study's view-following reconstructor."""

    def __init__(self, image_size: int, resolution: int = 64, radius: float = 1.0, footprint: bool = False):
        """`footprint`: keep a voxel when any part of it may touch each mask (`_carve`), not only its
        centre: what the refinement's start and sampling bounds need."""
        self.config = CarvedHullConfig(image_size=image_size, resolution=resolution, radius=radius)
        self.footprint = footprint

    def initial_state(self, batch: int = 1) -> CarvedHullState:
        if batch != 1:
            raise ValueError("the carved hull reconstructs one object at a time")
        r = self.config.resolution
        return CarvedHullState(None, np.zeros((r, r, r, 3), np.float32), np.zeros((r, r, r), np.float32))

    def update(self, state: CarvedHullState, views: ViewBatch) -> CarvedHullState:
        images = views.image[0].permute(0, 2, 3, 1).float().cpu().numpy()  # (V, H, W, 3) sRGB
        backgrounds = views.image_bg[0].permute(0, 2, 3, 1).float().cpu().numpy()
        rays = views.plucker[0].permute(0, 2, 3, 1).double().cpu().numpy()
        masks = [object_mask(images[v], backgrounds[v]) > 0 for v in range(len(images))]
        cameras = [camera_from_plucker(rays[v]) if masks[v].any() else None for v in range(len(images))]
        return self.update_known(state, cameras, list(images), masks)

    def update_known(self, state: CarvedHullState, cameras: list[Camera | None], images: list[np.ndarray],
                     masks: list[np.ndarray]) -> CarvedHullState:
        """The same update from views whose cameras and masks (bool, True = object) are known: a
        capture's own masks, rather than the ones `update` reads back from the white fill."""
        seen = [(camera, image, mask) for camera, image, mask in zip(cameras, images, masks)
                if camera is not None and mask.any()]  # a view without the object says nothing about where it is
        if not seen:
            return CarvedHullState(state.occupancy, state.colour_sum, state.weight, state.updates + 1)
        c = self.config
        occupancy = _ball(c.resolution, c.radius) if state.occupancy is None else state.occupancy.copy()
        hull = VoxelHull(occupancy, c.radius)
        for camera, _, mask in seen:
            _carve(hull, camera, mask, self.footprint)
        colour_sum, weight = state.colour_sum.copy(), state.weight.copy()
        surface = np.argwhere(hull.surface())  # the carved hull is the same for every view of the update
        if len(surface):
            normals = _outward_normals(hull.occupancy)[surface[:, 0], surface[:, 1], surface[:, 2]]
            inside = np.argwhere(hull.occupancy)
            for camera, image, mask in seen:
                self._add_colour(hull, surface, normals, inside, camera, image, mask, colour_sum, weight)
        return CarvedHullState(occupancy, colour_sum, weight, state.updates + 1)

    def _add_colour(self, hull: VoxelHull, surface: np.ndarray, normals: np.ndarray, inside: np.ndarray, camera: Camera,
                    image: np.ndarray, mask: np.ndarray, colour_sum: np.ndarray, weight: np.ndarray) -> None:
        """Splat one view's colours onto the occupied voxels (`inside`) just below the surface it sees
        (`surface` voxels with outward `normals`)."""
        h, w = mask.shape
        pixel, z = _pixels(camera, hull.centers_of(surface))
        ok = pixel >= 0
        # The z-buffer of the surface voxels, each covering the pixels round its centre's (a voxel is
        # about a pixel across at the study's sizes: the 3x3 minimum closes the gaps between them).
        depth = np.full(h * w, np.inf)
        np.minimum.at(depth, pixel[ok], z[ok])
        depth = cv2.erode(depth.reshape(h, w).astype(np.float32), np.ones((3, 3), np.uint8)).ravel()
        # Each pixel's facing weight comes from the surface voxel nearest the camera in it.
        order = np.flatnonzero(ok)[np.argsort(z[ok])[::-1]]  # far to near: the nearest write wins
        facing = np.zeros(h * w)
        to_camera = camera.center[None] - hull.centers_of(surface[order])
        cosine = np.sum(normals[order] * to_camera, axis=1) / np.maximum(np.linalg.norm(to_camera, axis=1), 1e-12)
        facing[pixel[order]] = cosine
        facing = cv2.dilate(facing.reshape(h, w).astype(np.float32), np.ones((3, 3), np.uint8)).ravel()
        # Every occupied voxel within the depth band under the visible surface takes the pixel's colour.
        pixel, z = _pixels(camera, hull.centers_of(inside))
        ok = pixel >= 0
        band = self.config.colour_depth_voxels * hull.voxel_size
        take = np.zeros(len(inside), bool)
        take[ok] = (z[ok] <= depth[pixel[ok]] + band) & mask.ravel()[pixel[ok]]
        cos_limit = np.cos(np.radians(self.config.max_angle_deg))
        take[ok] &= facing[pixel[ok]] >= cos_limit
        index, p = inside[take], pixel[take]
        wgt = facing[p]
        colours = image.reshape(-1, 3)[p]
        np.add.at(colour_sum, (index[:, 0], index[:, 1], index[:, 2]), colours * wgt[:, None])
        np.add.at(weight, (index[:, 0], index[:, 1], index[:, 2]), wgt)

    def decode(self, state: CarvedHullState) -> "HullField | SphereField":
        if state.occupancy is None or not state.occupancy.any():
            # Nothing seen, or the masks disagree everywhere: a speck, so the scores stay defined and poor.
            return SphereField(0.05, torch.full((3,), 0.5), self.config.radius)
        return HullField(state, self.config.radius)


def _ball(resolution: int, radius: float) -> np.ndarray:
    """The voxels whose centres lie in the ball of `radius`: where the object is before any view."""
    centres = -radius + (np.arange(resolution) + 0.5) * (2.0 * radius / resolution)
    x, y, z = np.meshgrid(centres, centres, centres, indexing="ij")
    return x**2 + y**2 + z**2 <= radius**2


def _carve(hull: VoxelHull, camera: Camera, mask: np.ndarray, footprint: bool = False) -> None:
    """Remove the voxels whose centres one view sees on background, in place.

    Tighter than the capture pipeline's carve_visual_hull, on purpose: that one keeps a voxel any part
    of which may touch a mask (plus slack), and counts one outside a photo's frame as unseen, which
    suits hand-made masks on whole photos. Here the masks are exact and each view is a crop holding
    the whole object, so a centre outside the crop is background too; the SDF puts the surface on the
    voxels' faces, which gives back the half voxel a centre test takes.

    With `footprint`, a voxel stays when its bounding ball may reach the mask (the distance from its
    projected centre to the nearest mask pixel at most the ball's projected radius and a pixel). A centre test
    loses parts thinner than a voxel: a panel of zero thickness (the glTF set's NormalTangentTest)
    kept 115 of its voxels at 128 px, and the refinement, whose samples stay inside that hull, could
    never represent it (README, "The refinement's hull, for thin parts")."""
    index = np.argwhere(hull.occupancy)
    pixel, z = _pixels(camera, hull.centers_of(index))
    on_object = np.zeros(len(index), bool)
    inside = pixel >= 0
    if footprint:
        # The ball's projected radius, and a pixel's diagonal: the mask and the projected centre are
        # both read at whole pixels.
        reach = VOXEL_HALF_DIAGONAL * hull.voxel_size * max(camera.fx, camera.fy) / z[inside] + math.sqrt(2.0)
        on_object[inside] = distance_to(mask).ravel()[pixel[inside]] <= reach
    else:
        on_object[inside] = mask.ravel()[pixel[inside]]
    gone = ~on_object & (z > 1e-6)  # behind the camera: it says nothing
    hull.occupancy[index[gone, 0], index[gone, 1], index[gone, 2]] = False


def _pixels(camera: Camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat pixel index of each point's projection (-1 when outside the image or behind) and its depth."""
    xy, z = camera.project(points)
    with np.errstate(invalid="ignore"):
        px, py = np.floor(xy[:, 0]), np.floor(xy[:, 1])
        ok = (z > 1e-9) & (px >= 0) & (px < camera.width) & (py >= 0) & (py < camera.height)
    index = np.where(ok, np.nan_to_num(py) * camera.width + np.nan_to_num(px), -1).astype(np.int64)
    return index, z


def _outward_normals(occupancy: np.ndarray) -> np.ndarray:
    """(R, R, R, 3) unit outward normals: minus the gradient of the smoothed occupancy."""
    smooth = ndimage.gaussian_filter(occupancy.astype(np.float32), 1.0)
    g = -np.stack(np.gradient(smooth), axis=-1)
    return g / np.maximum(np.linalg.norm(g, axis=-1, keepdims=True), 1e-9)


class HullField:
    """A voxel hull as a field (the renderer's duck-typed Field interface): a signed distance, colours
    and normals on the grid, read trilinearly."""

    def __init__(self, state: CarvedHullState, radius: float):
        occupancy = state.occupancy
        resolution = occupancy.shape[0]
        voxel = 2.0 * radius / resolution
        self.radius = float(radius)
        self.normal_eps = voxel
        # Signed distance to the voxels' boundary (negative inside), lightly smoothed for the normals.
        outside = ndimage.distance_transform_edt(~occupancy) - 0.5
        inside = ndimage.distance_transform_edt(occupancy) - 0.5
        sdf = ndimage.gaussian_filter(np.where(occupancy, -inside, outside) * voxel, 0.75).astype(np.float32)
        normals = np.stack(np.gradient(sdf), axis=-1)
        normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-9)
        coloured = state.weight > 0
        if coloured.any():
            colour = state.colour_sum / np.maximum(state.weight, 1e-12)[..., None]
            nearest = ndimage.distance_transform_edt(~coloured, return_distances=False, return_indices=True)
            colour = colour[nearest[0], nearest[1], nearest[2]]
        else:
            colour = np.full(occupancy.shape + (3,), 0.5, np.float32)
        colour = np.clip(colour, 0.0, 1.0).astype(np.float32)
        albedo = srgb_to_linear(colour).astype(np.float32)
        grid = lambda a: torch.from_numpy(np.ascontiguousarray(a.reshape(a.shape[:3] + (-1,)).transpose(3, 0, 1, 2)))[None]  # noqa: E731
        self._sdf = grid(sdf)
        self._values = grid(np.concatenate([colour, albedo, normals], axis=-1).astype(np.float32))

    def _read(self, volume: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
        """(B, N, 3) world points -> (B, N, C) trilinear values (the grid's border beyond it)."""
        shape = points.shape[:-1]
        # Array axes are (x, y, z) = (D, H, W); grid_sample's last coordinate runs along W, so reverse.
        where = (points.reshape(1, -1, 1, 1, 3).float().cpu() / self.radius).flip(-1)
        values = F.grid_sample(volume, where, mode="bilinear", padding_mode="border", align_corners=False)
        return values[0, :, :, 0, 0].T.reshape(*shape, -1).to(points.device)

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        return self._read(self._sdf, points)[..., 0]

    def sample(self, points: torch.Tensor, view_dirs: torch.Tensor | None = None) -> FieldSample:
        values = self._read(self._values, points)
        fill = lambda value: torch.full(points.shape[:-1], value, dtype=points.dtype, device=points.device)  # noqa: E731
        return FieldSample(sdf=self.sdf(points), albedo=values[..., 3:6], roughness=fill(BASELINE_ROUGHNESS),
                           metallic=fill(BASELINE_METALLIC), normal=F.normalize(values[..., 6:9], dim=-1),
                           colour=None if view_dirs is None else values[..., 0:3])
