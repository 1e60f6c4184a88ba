"""Where a refinement starts: the LIRM state's decoded field, the carved visual hull of the masks, the
hull's shape with the LIRM field's materials, or nothing; and the occupancy grid (the hull, dilated)
that bounds where every refinement samples."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from scipy import ndimage

from lirm.engine.evaluation.carved_hull import CarvedHull, CarvedHullState, HullField
from lirm.engine.model.config import LIRMConfig
from lirm.engine.model.field import Field, FieldHeads
from lirm.engine.model.occupancy_grid import OccupancyGrid

from .config import RefineConfig
from .objective import batch_loss, sdf_gradients
from .photo_carving import PhotoCarving, photo_carve_occupancy
from .ray_rendering import render_ray_batch
from .refinable_field import RefinableField, fresh_field
from .refine_views import RefineViews
from .unseen_hollow import UnseenHollow, hollow_below_opening

INITS = ("lirm", "hull", "hull-lirm", "scratch")
# "auto" (`lirm refine`'s default on a capture with no refinement yet): whichever of LIRM and
# hull-lirm agrees better with the photos (`closer_start`).


def masks_hull(views: RefineViews, resolution: int, radius: float, footprint: bool = False) -> CarvedHullState:
    """The visual hull of the views' masks, coloured from their pixels (evaluation/carved_hull.py).
    `footprint`: each voxel kept when any part of it may touch every mask, not only its centre."""
    hull = CarvedHull(image_size=views.images.shape[1], resolution=resolution, radius=radius, footprint=footprint)
    return hull.update_known(hull.initial_state(1), views.cameras, list(views.images), [m > 0.5 for m in views.masks])


@dataclass
class ViewsHulls:
    """The refinement's hulls of a set of views, and what the photos changed in them."""

    centres: CarvedHullState  # each voxel kept when its centre projects into every mask (the start)
    footprint: CarvedHullState  # ... when any part of it may (the sampling bounds: thin parts kept)
    carving: PhotoCarving | None = None  # where the photos see through them (None: not asked for)
    hollow: UnseenHollow | None = None  # the opening continued down (None: not asked for, or nothing carved)
    # (R, R, R) bool: what the carving and the hollow took from the footprint hull (None: nothing)
    opened: np.ndarray | None = None

    def sentences(self) -> list[str]:
        """What the carving and the hollow did, for the refinement's notes."""
        said = [self.carving.sentence()] if self.carving is not None and self.carving.carved_voxels else []
        return said + ([self.hollow.sentence()] if self.hollow is not None else [])


def views_hulls(views: RefineViews, config: RefineConfig, radius: float) -> ViewsHulls:
    """The masks' hull carved by each voxel's centre and by its footprint, both carved further where
    the photos see through them (`config.photo_carving`, photo_carving.py: a mug's opening) and below
    an opening whose bottom they did not see (`config.hollow_openings`, unseen_hollow.py)."""
    hull = masks_hull(views, config.hull_resolution, radius)
    footprint_hull = masks_hull(views, config.hull_resolution, radius, footprint=True)
    if not config.photo_carving or hull.occupancy is None or not hull.occupancy.any():
        return ViewsHulls(hull, footprint_hull)
    # Carved from the footprint hull, the fatter one: carved from the centres' hull, the footprint's
    # extra layer over a mug's opening stayed in the sampling bounds, and the fit grew a lid in it.
    carving = photo_carve_occupancy(footprint_hull.occupancy, radius, views.cameras, views.images, views.masks)
    removed = footprint_hull.occupancy & ~carving.occupancy
    hollow = None
    if config.hollow_openings and carving.carved_voxels:
        hollow = hollow_below_opening(footprint_hull.occupancy, carving)
    # The start loses the hollow's core only: its walls a voxel thicker than the bounds' (which are a
    # voxel fatter), as thick as the photos saw them.
    from_start = removed if hollow is None else removed | hollow.core
    from_bounds = removed if hollow is None else footprint_hull.occupancy & ~hollow.occupancy
    return ViewsHulls(_recoloured(hull, views, radius, ~from_start),
                      _recoloured(footprint_hull, views, radius, ~from_bounds, footprint=True), carving, hollow,
                      from_bounds if from_bounds.any() else None)


def _recoloured(state: CarvedHullState, views: RefineViews, radius: float, keep: np.ndarray,
                footprint: bool = False) -> CarvedHullState:
    """`state` with only the voxels in `keep`, coloured again from the views (the surface it shows has moved)."""
    resolution = state.occupancy.shape[0]
    hull = CarvedHull(image_size=views.images.shape[1], resolution=resolution, radius=radius, footprint=footprint)
    start = hull.initial_state(1)
    start.occupancy = state.occupancy & keep
    return hull.update_known(start, views.cameras, list(views.images), [m > 0.5 for m in views.masks])


def sampling_grid(hull: CarvedHullState, radius: float, dilation_voxels: int, device: str | torch.device = "cpu",
                  opened: np.ndarray | None = None) -> OccupancyGrid | None:
    """The hull, dilated by a few voxels for masks and poses that are not exact: no part of the
    object can lie outside it, so samples there are wasted. None when the masks carved everything
    away (inconsistent masks or poses): then the refinement samples the whole bounding sphere.
    `opened`: voxels the photos saw through or the hollow's prior emptied (ViewsHulls.opened); those
    the dilation leaves empty are marked in the grid for the outside term (outside_bounds.py). (The
    dilation reached only a voxel into them for a while: the synthetic mug measured the same, and the
    demo mug's rim lost a quarter of its top, README "The hollow that holds".)"""
    if hull.occupancy is None or not hull.occupancy.any():
        return None
    occupied = ndimage.binary_dilation(hull.occupancy, iterations=dilation_voxels) if dilation_voxels else hull.occupancy
    outside_opened = None
    if opened is not None and opened.any():
        outside_opened = torch.from_numpy(np.ascontiguousarray(opened & ~occupied)).to(device)
    return OccupancyGrid(torch.from_numpy(np.ascontiguousarray(occupied)).to(device), radius, outside_opened)


def views_sampling_grid(views: RefineViews, config: RefineConfig, radius: float,
                        hulls: ViewsHulls | None = None) -> OccupancyGrid | None:
    """Where the refinement of `views` samples: their masks' hull carved by each voxel's footprint
    (parts thinner than a voxel stay: a centre test lost a panel of zero thickness, and no sample
    could reach it), dilated by `config.hull_dilation_voxels`. The start from the hull keeps the
    centre test: a voxel fatter, it agreed less with the photos (README, "The refinement's hull,
    for thin parts"). `hulls`: views_hulls' result when the caller has made it (the footprint hull
    carved where the photos see through it, and what that opened)."""
    if hulls is None:
        return sampling_grid(masks_hull(views, config.hull_resolution, radius, footprint=True), radius,
                             config.hull_dilation_voxels, config.device)
    return sampling_grid(hulls.footprint, radius, config.hull_dilation_voxels, config.device, hulls.opened)


def footprint_keeps_lost_parts(centres: CarvedHullState, footprint: CarvedHullState, margin_voxels: int = 2,
                               fraction: float = 0.1) -> bool:
    """Whether the footprint hull holds parts the centres' hull lost (a panel thinner than a voxel),
    not only the voxel of fattening it has everywhere: more than `fraction` of its voxels lie beyond
    `margin_voxels` of the centres' hull. Only then is it worth a start candidate of its own (a hull
    regression, 5-9 s). On 2026-12-02's held-out objects (16 views, 64^3) that share was 0-2.8% for
    the four synthetic and six of the seven glTF models, and 55% for the panel of tiles (README)."""
    if footprint.occupancy is None or not footprint.occupancy.any():
        return False
    if centres.occupancy is None or not centres.occupancy.any():
        return True
    near = ndimage.binary_dilation(centres.occupancy, iterations=margin_voxels)
    beyond = np.count_nonzero(footprint.occupancy & ~near)
    return beyond > fraction * np.count_nonzero(footprint.occupancy)


def from_lirm(field: Field, resolution: int) -> RefinableField:
    """The decoded LIRM field, its planes resampled to `resolution`."""
    refinable = RefinableField.from_field(field)
    refinable.resample_planes(resolution)
    return refinable


def from_hull(hull: CarvedHullState, config: LIRMConfig, heads: FieldHeads | None, resolution: int, steps: int,
              seed: int = 0, cancel=None, materials: Field | None = None) -> RefinableField:
    """A field regressed onto the carved hull: its signed distance, colour and linearised albedo at
    points spread over the bounding sphere and crowded near the hull's surface. `heads`: the
    model's (the prior's decoders, as a starting point) or None for fresh ones. `materials`: a field
    (the LIRM state's) whose roughness and metallic, read at its own surface nearest each point,
    the regression takes too: the hull's shape (thin parts the prior lost) with the prior's
    materials (which the hull has none of)."""
    refinable = fresh_field(config, resolution, seed)
    if heads is not None:
        refinable = RefinableField.from_field(Field(config, heads, refinable.planes, refinable.panoramas))
    if hull.occupancy is None or not hull.occupancy.any():
        return refinable
    target = HullField(hull, config.radius)
    generator = torch.Generator().manual_seed(seed)
    surface = torch.from_numpy(_surface_points(hull.occupancy, config.radius)).float()
    optimiser = torch.optim.Adam([{"params": [refinable.planes], "lr": 2e-2},
                                  {"params": list(refinable.heads.parameters()), "lr": 2e-3}]
                                 + ([{"params": [refinable.panoramas], "lr": 1e-2}] if refinable.panoramas is not None else []),
                                 fused=True)
    voxel = 2.0 * config.radius / hull.occupancy.shape[0]
    for _ in range(steps):
        if cancel is not None and cancel():
            break
        near = surface[torch.randint(0, len(surface), (2048,), generator=generator)]
        near = near + torch.randn(near.shape, generator=generator) * 2.0 * voxel
        anywhere = (torch.rand(2048, 3, generator=generator) * 2.0 - 1.0) * config.radius
        points = torch.cat([near, anywhere])[None]
        with torch.no_grad():
            truth = target.sample(points, view_dirs=torch.zeros_like(points))
            towards = -truth.normal  # looking at the surface along its normal
        field = refinable.field()
        sample = field.sample(points, towards)
        band = 0.1 * config.radius  # far from the surface only the sign matters much
        loss = (sample.sdf.clamp(-band, band) - truth.sdf.clamp(-band, band)).abs().mean()
        loss = loss + (sample.colour - truth.colour).abs().mean() + (sample.albedo - truth.albedo).abs().mean()
        if materials is not None:
            roughness, metallic = materials_near(materials, points)
            loss = loss + (sample.roughness - roughness).abs().mean() + (sample.metallic - metallic).abs().mean()
        optimiser.zero_grad(set_to_none=True)
        loss.backward()
        optimiser.step()
    return refinable


@torch.no_grad()
def materials_near(field: Field, points: torch.Tensor, newton_steps: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    """(roughness, metallic) of `field` at its own surface nearest each of `points` (1, N, 3): each
    point moved along the SDF's gradient by its signed distance, twice. The heads are trained on
    surface points; what they say far off the surface (where the hull has parts the field lacks)
    means nothing."""
    moved = points
    for _ in range(newton_steps):
        distance = field.sdf(moved)
        normal = torch.nn.functional.normalize(sdf_gradients(field, moved[0], 0.5 * field.normal_eps), dim=-1)[None]
        moved = (moved - distance[..., None] * normal).clamp(-field.radius, field.radius)
    sample = field.sample(moved)
    return sample.roughness, sample.metallic


def _surface_points(occupancy: np.ndarray, radius: float) -> np.ndarray:
    surface = occupancy & ~ndimage.binary_erosion(occupancy)
    index = np.argwhere(surface)
    voxel = 2.0 * radius / occupancy.shape[0]
    return (-radius + (index + 0.5) * voxel).astype(np.float32)


def scratch(config: LIRMConfig, resolution: int, seed: int = 0) -> RefinableField:
    return fresh_field(config, resolution, seed)


@torch.no_grad()
def photo_loss(refinable: RefinableField, views: RefineViews, grid: OccupancyGrid | None, config: RefineConfig,
               rays: int = 4096) -> float:
    """The refinement's colour and mask loss of a starting field on a fixed batch of the views' rays at
    the final 1/beta: how far a start is from the photos (the same rays for every candidate)."""
    generator = torch.Generator().manual_seed(config.seed + 1)
    index = views.sample_rays(rays, config.edge_ray_fraction, generator)
    field = refinable.field()
    render = render_ray_batch(field, views.origins[index], views.directions[index], grid, 1.0 / config.inv_beta[1],
                              config.coarse_samples, config.fine_samples, generator)
    # Only the colour and the mask: no surface points are sampled (eikonal_points 0), and with them
    # the curvature term's mean over none was NaN, so every comparison of starts was False (which
    # made `--init auto` always take the hull until 2026-11-29; batch_loss now skips those terms).
    weights = type(config.losses)(colour=1.0, mask=config.losses.mask, eikonal=0.0, normal=0.0, albedo=0.0,
                                  material_prior=0.0, plane_tv=0.0)
    loss, _ = batch_loss(field, render, views.colours[index], views.alphas[index], weights, 0, generator)
    if not torch.isfinite(loss):
        raise ValueError(f"the starting field's photo loss is {float(loss)}: its colours or SDF are not finite")
    return float(loss)


def closer_start(from_lirm: RefinableField, from_hull: RefinableField, views: RefineViews, grid: OccupancyGrid | None,
                 config: RefineConfig, from_footprint_hull: RefinableField | None = None) -> tuple[RefinableField, str, dict[str, float]]:
    """The start of `lirm refine --init auto`: a prior that does not yet follow its photos can start
    further from them than the masks' hull does, so whichever of the candidates agrees best with the
    views (`photo_loss` on the same rays; LIRM on a tie, then the centres' hull). Returns the field,
    "lirm", "hull-lirm" or "hull-lirm-footprint", and every candidate's loss. `from_footprint_hull`:
    the hull carved by each voxel's footprint (`masks_hull(footprint=True)`) with the prior's
    materials: a voxel fatter where the centres' hull is right, whole where it lost parts thinner
    than a voxel (README, "The refinement's hull, for thin parts")."""
    if config.rays_through_hull and grid is not None and views.uniform_index is None:
        # The rays the fit itself draws (found once for both): those that miss the hull are alike for every start.
        views = views.through_grid(grid, from_lirm.config.radius)
    candidates = {"lirm": from_lirm, "hull-lirm": from_hull}
    if from_footprint_hull is not None:
        candidates["hull-lirm-footprint"] = from_footprint_hull
    losses = {name: photo_loss(candidate, views, grid, config) for name, candidate in candidates.items()}
    best = min(losses, key=losses.get)  # the first of equals: the order above
    return candidates[best], best, losses
