"""Fitting the exported textures to the photos: the last step of an export with inverse-rendered materials.

The baked textures are the field's albedo, roughness and metallic read at each texel. The relit
asset is those textures on the exported mesh, shaded by the renderer, and what it shows differs
from the field's volume rendering: the mesh is a decimated marching-cubes surface, the texels are
queried on the zero level set rather than blended along each ray, and the field's own fit stops
at a time budget. Here the textures themselves are fitted, as nvdiffrec's second stage fits its
textures on a fixed mesh: the mesh (with its normal map) is rasterised from every photo's camera
through the renderer's G-buffer, so each photo pixel knows the texel it shows and the shading normal
the renderer will use; the texels' albedo, roughness and metallic are shaded there under the
lighting fitted with the materials (the renderer's split-sum model, in torch) and held to the
photo through the camera's tone curve (L1, the refinement's photometric term). The mesh, normals
and lighting stay fixed, so the lighting's terms are tabulated once per pixel (tabulated_lighting.py)
and a step costs a texture lookup and a shading: a few seconds for a capture on the CPU.

Roughness and metallic are held to the field's values by a quadratic prior: a handful of views say
little about them per texel, and without it they scatter into noise. Texels no photo pixel samples
keep the field's values. On the held-out synthetic set it raised the relighting PSNR (README,
"Lighting and materials").

That prior also keeps metal the field left as paint from being found by the gradient (a local
minimum: metal_search.py), so by default each texel's material is first chosen among three fits
(the field's metallic, metallic held at 0, held at 1) and the joint fit starts from the choice.

An export's texture much finer than its photos is fitted at the photos' resolution and the change
carried back up (fit_resolution.py): texel for texel, a photo pixel's few sub-samples leave a speckle.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from lirm.engine.lighting.camera_response import radiance_to_display_torch
from lirm.engine.lighting.footprint_shading import shade_footprints
from lirm.engine.lighting.tabulated_lighting import TabulatedLighting

from .fit_resolution import averaged_down, carried_up, fit_size_for, texels_per_photo_pixel
from .metal_search import AS_FITTED, DIELECTRIC, METAL, choose_hypotheses
from .photo_registration import PhotoSources, ViewWarps, photo_sources, read_photos
from .surface_heights import SurfaceHeights
from .texel_reads import TexelReads
from .texture_bake import BakedTextures, dilate
from .uv_atlas import UVMesh

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class TextureFitConfig:
    steps: int = 200
    learning_rate: float = 0.02  # Adam, on the textures' logits
    # Weight of the squared distance of roughness and metallic from the field's (after the metal search:
    # from the chosen fit's). 0.1 relit the same saved fields a little better (synthetic set +0.18 dB
    # PSNR-L, glTF pair +0.13) but only by letting roughness drift from the truth (the export's own
    # roughness PSNR -1.0 dB; 0.3: +0.10 / +0.13 dB for -0.34): not adopted (README, "The material
    # prior in the texture fit").
    material_prior: float = 1.0
    fit_materials: bool = True  # False: the albedo alone
    min_photo_alpha: float = 0.99  # photo pixels less covered than this (the mask's soft edge) are left out
    lighting_levels: int = 12  # roughness levels the lighting is tabulated at
    # A photo channel at or above this is clipped (capture_lighting's level): the camera saw at least
    # that much, so only a prediction below the level is wrong there (None: plain L1 everywhere).
    clip_level: float | None = 250.0 / 255.0
    # At most this many photo pixels (a seeded random subset beyond it): bounds a step's time and the
    # tabulated lighting's memory for captures of many large photos (the synthetic set's 16 crops of
    # 128 px give 62k-131k, the demo's 16 photos 463k). On the demo mug 150k left visibly noisier
    # texels than 300k (fewer pixels per texel), for 20 s of fitting against 33 s.
    max_pixels: int = 300_000
    # Sub-samples per side of each photo pixel: the pixel is shaded at k x k points of its footprint
    # and their mean (in linear light, as a sensor integrates) is held to the photo. With 1, a pixel
    # is one point, and at about 3 texels per photo pixel most texels are pulled by one pixel or none.
    # 2 relit the synthetic set 0.14 dB and the glTF pair 0.12 dB better than 1 (every object), 3 only
    # 0.02 dB more than 2; the fit takes about 3 times as long (README, "The pixel footprint").
    footprint: int = 2
    # True: a pixel's sub-samples are pooled before shading, their texture reads and their lighting's
    # tabulated terms averaged and shaded once (a box-filtered read), instead of shaded each and their
    # radiance averaged. The same texels pulled, a quarter of the shading's work at a footprint of 2;
    # it differs from the exact mean only where a pixel's material and its light both vary inside it.
    # Paired on the same refined fields (synthetic objects 0-3): relight PSNR-L / PSNR-H 24.81 / 28.94
    # shading each sub-sample, 24.88 / 28.90 pooled (PSNR-L as good or better on every object), the
    # fit 19.7 s -> 12.7 s an object; on the glTF pair 23.71 / 27.61 -> 23.57 / 27.56 (the WaterBottle's
    # metal -0.24), 17.0 -> 14.1 s; the demo capture's fit 127.5 s -> 84.4 s (README, "The pooled
    # footprint"). The metal search then shades the pooled pixels too (search_one_sample is moot).
    pooled_footprint: bool = True
    seed: int = 0
    dilation: int = 16  # as the bake: texels grown into the gutters
    # Each texel's material chosen among three fits before the joint one (metal_search.py): the field's
    # metallic, metallic held at 0, held at 1. Finds metal the field left as paint (README: its worth).
    metal_search: bool = True
    search_steps: int = 100  # steps of each of the three fits (150 gave the same relighting)
    search_final_steps: int = 100  # steps of the joint fit after the choice (instead of `steps`)
    metal_search_sigma: float = 2.0  # texels: the neighbourhood whose summed error each choice reads
    metal_search_margin: float = 0.1  # the field's hypothesis is kept unless another's error is this share lower
    # The search's three fits shade one sub-sample of each pixel's footprint (the joint fit after it
    # all of them): the search only chooses per texel, from errors pooled over a few texels. Halves
    # the fit's time at a footprint of 2 (a synthetic object's 99 s -> 50 s) and relit the same (synthetic
    # set 22.06 -> 22.06 dB PSNR-L, glTF pair 23.82 -> 23.79; README, "The pixel footprint").
    search_one_sample: bool = True
    # Registration (photo_registration.py): before the fits, each photo gets a register_grid x
    # register_grid lattice of pixel offsets, fitted with the textures for register_steps, and the
    # photos are read at the registered positions from then on. 0: off.
    register_grid: int = 0
    register_steps: int = 100
    register_max_shift: float = 3.0  # pixels
    register_smooth: float = 0.01  # weight of the lattice's smoothness (pixels², against a mean L1 of display values)
    register_anchor: float = 0.01  # weight of the mean squared offset (pixels²): the smallest warps that agree
    register_learning_rate: float = 0.05  # Adam, pixels a step at most
    # Registration through the surface instead (surface_heights.py; the default): a register_heights x
    # register_heights map of heights along the normal over the atlas, shared by all photos, each
    # photo pixel read where its raised point projects, and the export's surface moved by it. 0: off
    # (one of the two registrations at most). Relit the synthetic set +0.59 dB PSNR-L (every object),
    # the glTF pair -0.11 (the WaterBottle's unfound metal -0.36), the demo's sheet -0.07; the fit
    # takes about 1.5 times as long (README, "Registering through the surface").
    register_heights: int = 128
    register_max_height: float = 0.02  # field units (the object's radius is about 1); 0.05 cost the WaterBottle 1.2 dB
    height_smooth: float = 0.1  # weight of the height map's smoothness (units of register_max_height squared)
    height_anchor: float = 0.01  # weight of the mean squared height (the same units)
    height_learning_rate: float = 0.002  # Adam, field units a step at most
    # The size the textures are fitted at (fit_resolution.py): None, the largest halving of the
    # export's size at which a photo pixel spans at most `max_texels_per_pixel` texels (median); an
    # int, that size. The fit's change is carried back up to the export's size.
    fit_size: int | None = None
    max_texels_per_pixel: float = 2.5

    def __post_init__(self) -> None:
        if self.steps < 0:
            raise ValueError(f"steps must be >= 0, got {self.steps}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        if self.footprint < 1:
            raise ValueError(f"footprint must be >= 1 sub-sample per side, got {self.footprint}")
        if self.register_grid == 1 or self.register_grid < 0 or self.register_steps < 1 or not self.register_max_shift > 0:
            raise ValueError(f"registration needs register_grid 0 (off) or >= 2, register_steps >= 1 and a positive "
                             f"register_max_shift, got {self.register_grid}, {self.register_steps}, {self.register_max_shift}")
        if self.register_heights == 1 or self.register_heights < 0:
            raise ValueError(f"registration through the surface needs register_heights 0 (off) or >= 2, got {self.register_heights}")
        if not self.max_texels_per_pixel > 0 or (self.fit_size is not None and self.fit_size < 1):
            raise ValueError(f"max_texels_per_pixel must be positive and fit_size None or >= 1, got "
                             f"{self.max_texels_per_pixel} and {self.fit_size}")
        if self.search_steps < 1 or self.search_final_steps < 0:
            raise ValueError(f"the metal search needs search_steps >= 1 and search_final_steps >= 0, "
                             f"got {self.search_steps} and {self.search_final_steps}")


@dataclass
class PhotoViews:
    """What the fit reads of each photo: its camera, its display-sRGB image and its object mask."""

    cameras: list
    images: np.ndarray  # (V, H, W, 3) display sRGB in [0, 1]
    masks: np.ndarray  # (V, H, W) in [0, 1]


@dataclass
class TextureFitReport:
    views: int
    pixels: int  # photo pixels fitted
    steps: int
    seconds: float
    loss_before: float  # mean photometric L1 (display values) of the baked textures
    loss_after: float
    stopped: bool = False
    metal_share: float | None = None  # of the covered texels, chosen as metal by the metal search (None: no search)
    dielectric_share: float | None = None  # chosen as paint (metallic 0) against the field's metallic
    registration_shift: float | None = None  # mean offset (pixels) the registration moved the photo pixels by (None: off)
    # The registration through the surface's height map (S, S) over the atlas, field units (None: not
    # that registration): the export moves its surface by it (surface_heights.displaced).
    surface_heights: np.ndarray | None = None
    fit_size: int | None = None  # the size the textures were fitted at, when below the export's (fit_resolution.py)
    texels_per_pixel: float | None = None  # a photo pixel's median side in texels of the export's textures

    def summary(self) -> str:
        text = (f"textures fitted to {self.views} photos ({self.pixels} pixels, {self.steps} steps, {self.seconds:.1f} s): "
                f"photometric error {self.loss_before:.4f} -> {self.loss_after:.4f}")
        if self.metal_share is not None:
            text += (f"; metal search: {100 * self.metal_share:.1f}% of the texels metal, "
                     f"{100 * self.dielectric_share:.1f}% paint, the rest as the field had them")
        if self.registration_shift is not None:
            text += f"; photos registered (mean shift {self.registration_shift:.2f} px)"
        if self.surface_heights is not None:
            text += f"; surface moved by {float(np.abs(self.surface_heights).mean()):.4f} on average"
        if self.fit_size is not None:
            text += (f"; fitted at {self.fit_size} px, the photos' resolution (a photo pixel spans "
                     f"{self.texels_per_pixel:.1f} texels of the export's)")
        return text


@dataclass
class PixelSamples:
    """The photo pixels that see the mesh: where they land in the atlas and how they are shaded. Each
    of the N pixels has `footprint` sub-samples (consecutive rows of uv, normal and view)."""

    uv: torch.Tensor  # (N * footprint, 2) glTF texture coordinates
    normal: torch.Tensor  # (N * footprint, 3) world shading normal (after the normal map), as the renderer shades
    view: torch.Tensor  # (N * footprint, 3) unit surface-to-eye direction
    colour: torch.Tensor  # (N, 3) the photo's display sRGB
    footprint: int = 1  # sub-samples per pixel (k x k for a footprint of k per side)
    sources: PhotoSources | None = None  # where each pixel lies in its photo (needed by the registration)

    @property
    def pixels(self) -> int:
        return int(self.colour.shape[0])

    def one_sample(self) -> "PixelSamples":
        """The same pixels, each shaded at its first sub-sample only (itself, with a footprint of 1)."""
        if self.footprint == 1:
            return self
        f = self.footprint
        return PixelSamples(self.uv[::f], self.normal[::f], self.view[::f], self.colour, 1, self.sources)

    @property
    def pixel_uv(self) -> torch.Tensor:
        """(N, 2): each pixel's first sub-sample's coordinates (a mean could fall between charts)."""
        return self.uv[:: self.footprint]

    def subset(self, count: int, seed: int = 0) -> "PixelSamples":
        """At most `count` of the pixels, drawn at random (the same ones for the same seed)."""
        total = self.pixels
        if total <= count:
            return self
        keep = torch.randperm(total, generator=torch.Generator().manual_seed(seed))[:count]
        rows = (keep[:, None] * self.footprint + torch.arange(self.footprint)).reshape(-1)
        return PixelSamples(self.uv[rows], self.normal[rows], self.view[rows], self.colour[keep], self.footprint,
                            self.sources.subset(keep) if self.sources is not None else None)


def mesh_for_rendering(uv_mesh: UVMesh, textures: BakedTextures):
    """The export's mesh and baked textures as the renderer's MeshData (the field's frame)."""
    from lirm.renderer.material import PBRMaterial
    from lirm.renderer.mesh import MeshData

    material = PBRMaterial(name="baked", base_color_texture=textures.base_color_srgb8(),
                           metallic_roughness_texture=textures.metallic_roughness8(), normal_texture=textures.normal8())
    return MeshData(uv_mesh.positions, uv_mesh.faces, normals=uv_mesh.normals, uvs=uv_mesh.uvs, tangents=uv_mesh.tangents,
                    material=material, name="export")


def sample_photo_pixels(mesh, photos: PhotoViews, context, min_photo_alpha: float = 0.99, footprint: int = 1,
                        with_sources: bool = False) -> PixelSamples:
    """Rasterise `mesh` (MeshData) from every photo's camera and keep the pixels that both the render
    (fully covered, not an edge, a finite normal, in every sub-sample) and the photo's mask call
    object; with `footprint` k, each pixel at k x k sub-samples (the camera scaled by k). With
    `with_sources`, also where each pixel lies in its photo (only the registration reads it, and it
    holds a copy of the photos)."""
    from lirm.renderer.environment import Environment
    from lirm.renderer.pbr_renderer import PBRRenderer, RenderSettings

    renderer = PBRRenderer(context)
    scene = renderer.upload([mesh])
    # The G-buffer's texture coordinates and normals do not depend on the light; any will do.
    lighting = renderer.prepare_lighting(Environment(np.full((8, 16, 3), 0.5, np.float32), "grey"))
    uv, normal, view, colour, pixel_xy, parallax = [], [], [], [], [], []
    try:
        k = footprint
        for camera, image, mask in zip(photos.cameras, photos.images, photos.masks):
            if (int(camera.height), int(camera.width)) != np.asarray(mask).shape[:2]:
                raise ValueError(f"a photo of {mask.shape[1]}x{mask.shape[0]} px has a camera of "
                                 f"{int(camera.width)}x{int(camera.height)} px")
            fine = camera.scaled(k) if k > 1 else camera
            out = renderer.render_view(scene, fine, lighting, RenderSettings(show_environment=False, supersample=1))
            _, directions = fine.pixel_rays()
            # (kH, kW, C) -> (H, W, k*k, C): each photo pixel's sub-samples together
            group = lambda a: a.reshape(a.shape[0] // k, k, a.shape[1] // k, k, -1).transpose(0, 2, 1, 3, 4).reshape(  # noqa: E731
                a.shape[0] // k, a.shape[1] // k, k * k, -1)
            # A pixel whose G-buffer is not finite (a zero vertex normal normalised to NaN) cannot be
            # shaded, and one NaN reaching the BRDF table's lookup would end the whole fit.
            pixel_uv, pixel_normal = group(out.uv), group(out.normal)
            finite = (np.isfinite(pixel_normal).all(-1) & np.isfinite(pixel_uv).all(-1)).all(-1)
            covered = (group(out.mask[..., None])[..., 0] > 0.999).all(-1)
            use = covered & (np.asarray(mask) >= min_photo_alpha) & finite
            uv.append(pixel_uv[use].reshape(-1, 2))
            normal.append(pixel_normal[use].reshape(-1, 3))
            view.append(-group(directions)[use].reshape(-1, 3))
            colour.append(np.asarray(image)[use])
            if with_sources:
                rows, columns = np.nonzero(use)  # the same row-major order as the boolean selections above
                pixel_xy.append(np.stack([columns + 0.5, rows + 0.5], -1))
                parallax.append(_parallax(camera, fine, group(directions)[use], group(out.depth[..., None])[use],
                                          pixel_normal[use]))
    finally:
        scene.release()
        lighting.maps.release()
        renderer.release()
    as_tensor = lambda parts, width: torch.from_numpy(  # noqa: E731
        np.concatenate(parts).astype(np.float32) if parts else np.zeros((0, width), np.float32))
    n = as_tensor(normal, 3)
    n = n / n.norm(dim=-1, keepdim=True).clamp(min=1e-12)
    return PixelSamples(as_tensor(uv, 2), n, as_tensor(view, 3), as_tensor(colour, 3), footprint * footprint,
                        photo_sources(pixel_xy, photos.images, photos.masks, parallax) if with_sources else None)


def _parallax(camera, fine, directions: np.ndarray, depth: np.ndarray, normal: np.ndarray, step: float = 1e-3) -> np.ndarray:
    """(n, 2) pixels each pixel's surface point moves in `camera`'s image per unit it is raised along
    its normal: the projection's derivative, numerically. `directions`, `depth` (camera z) and
    `normal` are the pixels' sub-samples (n, k*k, C) as `fine` (the camera scaled) rendered them; the
    pixel's point and normal are their means."""
    along = depth / np.maximum(directions @ fine.rotation[:, 2], 1e-6)[..., None]
    point = (fine.center + directions * along).mean(1)
    n = normal.mean(1)
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    raised, _ = camera.project(point + step * n)
    here, _ = camera.project(point)
    return ((raised - here) / step).astype(np.float32)


METAL_HELD = (0.02, 0.98)  # the metallic the dielectric and metal hypotheses are held at (logits stay finite)


def _logit(values: np.ndarray) -> torch.Tensor:
    return torch.logit(torch.from_numpy(np.clip(values, 0.01, 0.99).astype(np.float32)))


class _Shading:
    """The photometric error of texture logits at the sampled pixels, under the tabulated lighting."""

    def __init__(self, samples: PixelSamples, lighting, config: TextureFitConfig, tabulated: TabulatedLighting | None = None):
        """`tabulated`: the lighting already tabulated at these samples (else it is, here)."""
        self.samples = samples
        self.light = tabulated if tabulated is not None else TabulatedLighting(lighting, samples.normal, samples.view,
                                                                               config.lighting_levels)
        # pooled: each pixel's sub-samples read and lit as one (TextureFitConfig.pooled_footprint)
        self.pool = samples.footprint if config.pooled_footprint else 1
        if self.pool > 1 and self.light.count == samples.uv.shape[0]:
            self.light = self.light.pooled(self.pool)
        self.reads: TexelReads | None = None  # made at the first step, when the textures' size is known
        self.clip_level = config.clip_level
        self.camera_response = lighting.camera_response  # the photos' tone curve, as the refinement had it
        self.use_colour(samples.colour)

    def use_colour(self, colour: torch.Tensor) -> None:
        """The photo colours (N, 3) the errors are measured against from now on (the registered ones)."""
        self.colour = colour
        self.clipped = self._clipped(colour)

    def _clipped(self, colour: torch.Tensor) -> torch.Tensor | None:
        """Which channels of `colour` are at the clip level (None: no clip level)."""
        return colour >= self.clip_level if self.clip_level is not None else None

    def errors(self, albedo_logit: torch.Tensor, roughness_logit: torch.Tensor, metallic_logit: torch.Tensor,
               colour: torch.Tensor | None = None) -> torch.Tensor:
        """(N, 3) absolute display-value error per pixel and channel (against `colour`, or the colours in use)."""
        samples = self.samples
        clipped = self.clipped if colour is None else self._clipped(colour)
        colour = self.colour if colour is None else colour
        if self.reads is None or self.reads.size != albedo_logit.shape[0]:
            self.reads = TexelReads(samples.uv, albedo_logit.shape[0], self.pool)
        # all five channels in one read: albedo (3), roughness, metallic
        texels = torch.sigmoid(torch.cat([albedo_logit, roughness_logit, metallic_logit], -1))
        read = self.reads(texels)
        # the pixel integrates its footprint in linear light (tabulated_lighting.shade's model, by hand)
        shaded = shade_footprints(self.light, read, samples.footprint // self.pool)
        predicted = radiance_to_display_torch(shaded, self.camera_response)
        difference = predicted - colour
        if clipped is not None:  # (the tone curve never reaches 1: a clipped value is compared with the level)
            difference = torch.where(clipped, (self.clip_level - predicted).clamp(min=0.0), difference)
        return difference.abs()


@dataclass
class _Logits:
    albedo: torch.Tensor  # (S, S, 3)
    roughness: torch.Tensor  # (S, S, 1)
    metallic: torch.Tensor  # (S, S, 1)


def _fit(shading: _Shading, start: _Logits, config: TextureFitConfig, steps: int, fit_metallic: bool,
         prior: tuple[torch.Tensor, torch.Tensor], progress: Callable[[int], None] | None = None,
         should_stop: Callable[[], bool] | None = None, registration: "_Registration | None" = None
         ) -> tuple[_Logits, int, bool]:
    """Adam on the logits from `start` for `steps`; roughness (and metallic when fitted) held to
    `prior` (their values, (S, S, 1)) by the quadratic prior. With a `registration`, the photos are
    read through its warps at every step and they are fitted too. Returns the logits, the steps
    taken and whether `should_stop` ended it."""
    warps = registration.warps if registration is not None else None
    albedo = torch.nn.Parameter(start.albedo.clone())
    roughness = torch.nn.Parameter(start.roughness.clone())
    metallic = torch.nn.Parameter(start.metallic.clone())
    params = [albedo] + ([roughness] + ([metallic] if fit_metallic else []) if config.fit_materials else [])
    groups = [{"params": params, "lr": config.learning_rate}]
    if warps is not None:
        groups.append({"params": list(warps.parameters()), "lr": registration.learning_rate})
    optimiser = torch.optim.Adam(groups, fused=True)  # as the refinement's (refiner.py)
    taken, stopped = 0, False
    with torch.enable_grad():  # callers score under no_grad (the evaluation); this fit needs its gradients
        for step in range(steps):
            if should_stop is not None and should_stop():
                stopped = True
                break
            if warps is None:
                loss = shading.errors(albedo, roughness, metallic).mean()
            else:  # pixels whose registered place leaves their photo's mask say nothing this step
                colour, alpha = read_photos(shading.samples.sources, warps.offsets(shading.samples.sources))
                inside = (alpha.detach() >= config.min_photo_alpha).float()
                error = shading.errors(albedo, roughness, metallic, colour).mean(-1)
                loss = (error * inside).sum() / inside.sum().clamp(min=1.0) + registration.smooth * warps.smoothness()
                loss = loss + registration.anchor * warps.magnitude()
            if config.fit_materials and config.material_prior:
                held = ((torch.sigmoid(roughness) - prior[0]) ** 2).mean()
                if fit_metallic:
                    held = held + ((torch.sigmoid(metallic) - prior[1]) ** 2).mean()
                loss = loss + config.material_prior * held
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            taken = step + 1
            if progress is not None:
                progress(step)
    return _Logits(albedo.detach(), roughness.detach(), metallic.detach()), taken, stopped


def fit_textures(textures: BakedTextures, samples: PixelSamples, lighting, config: TextureFitConfig = TextureFitConfig(),
                 progress: Progress | None = None, should_stop: Callable[[], bool] | None = None,
                 views: int = 0) -> tuple[BakedTextures, TextureFitReport]:
    """The textures fitted to the sampled photo pixels under `lighting` (a PanoramaLighting or any
    lighting `shade` accepts); the normal map and coverage are kept. With config.metal_search, each
    texel's material is first chosen among three fits (metal_search.py), then fitted jointly."""
    start = time.perf_counter()
    count = samples.pixels
    if count == 0 or config.steps == 0:
        return textures, TextureFitReport(views, count, 0, time.perf_counter() - start, float("nan"), float("nan"))
    if isinstance(lighting, torch.nn.Module):  # the fit runs on the CPU: a copy there, the caller's stays put
        lighting = copy.deepcopy(lighting).cpu().requires_grad_(False)
    shading = _Shading(samples, lighting, config)
    baked = _Logits(_logit(textures.base_color), _logit(textures.roughness[..., None]), _logit(textures.metallic[..., None]))
    searching = config.metal_search and config.fit_materials
    registering = config.register_grid > 0 or config.register_heights > 0
    final_steps = config.search_final_steps if searching else config.steps
    register_steps = config.register_steps if registering else 0
    total = register_steps + final_steps + (3 * config.search_steps if searching else 0)
    done = 0

    def tick(step: int) -> None:
        if progress and (done + step) % 20 == 0:
            if done + step < register_steps:
                what = "registering the photos"
            elif searching and done < register_steps + 3 * config.search_steps:
                what = "choosing metal or not per texel"
            else:
                what = "fitting the textures to the photos"
            progress(f"{what} ({done + step}/{total})", done + step, total)

    with torch.no_grad():
        loss_before = float(shading.errors(baked.albedo, baked.roughness, baked.metallic).mean())
    stopped, steps, choice, shift, heights = False, 0, None, None, None
    begin = baked
    prior = (torch.sigmoid(baked.roughness), torch.sigmoid(baked.metallic))
    # (The registration's fit shading one sub-sample per pixel, as the search does, saved 3 s of an
    # object's 26 and relit the synthetic set 0.47 dB worse, every object: README, "The texture fit's pace".)
    if registering:
        shift, heights, steps, stopped = _register(shading, baked, config, prior, tick, should_stop)
        done = steps
    if searching and not stopped:
        search_shading = shading
        if config.search_one_sample and samples.footprint > 1 and not config.pooled_footprint:
            search_shading = _Shading(samples.one_sample(), lighting, config,
                                      shading.light.rows(slice(None, None, samples.footprint)))
            search_shading.use_colour(shading.colour)  # (the registered colours, when registered)
        begin, prior, choice, taken, stopped = _search_metal(search_shading, baked, textures.base_color.shape[0], config,
                                                              tick, should_stop)
        steps += taken
        done = steps
    if not stopped:
        fitted, taken, stopped = _fit(shading, begin, config, final_steps, True, prior, tick, should_stop)
        steps += taken
    else:
        fitted = begin
    with torch.no_grad():
        loss_after = float(shading.errors(fitted.albedo, fitted.roughness, fitted.metallic).mean())
        as_texture = lambda logit: torch.sigmoid(logit).numpy()  # noqa: E731
        covered = textures.covered
        out = BakedTextures(dilate(as_texture(fitted.albedo), covered, config.dilation),
                            dilate(as_texture(fitted.roughness), covered, config.dilation)[..., 0],
                            dilate(as_texture(fitted.metallic), covered, config.dilation)[..., 0],
                            textures.normal, covered)
    report = TextureFitReport(views, count, steps, time.perf_counter() - start, loss_before, loss_after, stopped)
    report.registration_shift = shift
    report.surface_heights = heights
    if choice is not None:
        report.metal_share = choice.share(METAL, covered)
        report.dielectric_share = choice.share(DIELECTRIC, covered)
    return out, report


@dataclass
class _Registration:
    """What moves where the photos are read, and how it is fitted and held."""

    warps: torch.nn.Module  # ViewWarps or SurfaceHeights: offsets(sources), smoothness(), magnitude(), mean_shift(sources)
    learning_rate: float
    smooth: float
    anchor: float

    @classmethod
    def of(cls, config: TextureFitConfig, samples: PixelSamples) -> "_Registration":
        if config.register_grid:  # the lattice, when asked for, in place of the heights
            return cls(ViewWarps(samples.sources.views, config.register_grid, config.register_max_shift),
                       config.register_learning_rate, config.register_smooth, config.register_anchor)
        return cls(SurfaceHeights(config.register_heights, config.register_max_height, samples.pixel_uv),
                   config.height_learning_rate, config.height_smooth, config.height_anchor)


def _register(shading: _Shading, baked: _Logits, config: TextureFitConfig, prior: tuple[torch.Tensor, torch.Tensor],
              tick: Callable[[int], None], should_stop: Callable[[], bool] | None) -> tuple[float, np.ndarray | None, int, bool]:
    """Fit the registration's warps (a lattice per photo, or the heights over the surface) with the
    textures (from the baked ones), then let the shading read every pixel's colour at its registered
    place; the textures of this fit are not kept (the fits after it start from the baked ones again,
    now against registered photos). A pixel whose registered place leaves its photo's mask keeps its
    own colour. Returns the mean shift (pixels), the height map (SurfaceHeights only, else None), the
    steps taken and whether `should_stop` ended it."""
    sources = shading.samples.sources
    if sources is None:
        raise ValueError("registering the photos needs each pixel's place in its photo (sample_photo_pixels records it)")
    registration = _Registration.of(config, shading.samples)
    _, taken, stopped = _fit(shading, baked, config, config.register_steps, True, prior, tick, should_stop,
                             registration=registration)
    with torch.no_grad():
        colour, alpha = read_photos(sources, registration.warps.offsets(sources))
        shading.use_colour(torch.where((alpha >= config.min_photo_alpha)[:, None], colour, shading.samples.colour))
    heights = registration.warps.cells()[0, 0].detach().numpy() if isinstance(registration.warps, SurfaceHeights) else None
    return registration.warps.mean_shift(sources), heights, taken, stopped


def _search_metal(shading: _Shading, baked: _Logits, size: int, config: TextureFitConfig, tick: Callable[[int], None],
                  should_stop: Callable[[], bool] | None):
    """Three fits (metallic as the field has it, held at 0, held at 1), the per-texel choice among
    them, and where the joint fit then starts and what its prior holds roughness and metallic to."""
    low = torch.full_like(baked.metallic, float(torch.logit(torch.tensor(METAL_HELD[0]))))
    high = torch.full_like(baked.metallic, float(torch.logit(torch.tensor(METAL_HELD[1]))))
    starts = {AS_FITTED: baked, DIELECTRIC: _Logits(baked.albedo, baked.roughness, low),
              METAL: _Logits(baked.albedo, baked.roughness, high)}
    roughness_prior, metallic_prior = torch.sigmoid(baked.roughness), torch.sigmoid(baked.metallic)
    fits, errors, steps = {}, [], 0
    for which in (AS_FITTED, DIELECTRIC, METAL):
        offset = steps
        fits[which], taken, stopped = _fit(shading, starts[which], config, config.search_steps, which == AS_FITTED,
                                           (roughness_prior, metallic_prior), lambda step: tick(offset + step), should_stop)
        steps += taken
        if stopped:  # cancelled mid-search: what the field's own hypothesis reached is kept
            return fits[AS_FITTED], (roughness_prior, metallic_prior), None, steps, True
        with torch.no_grad():
            e = fits[which]
            errors.append(shading.errors(e.albedo, e.roughness, e.metallic).sum(-1).numpy())
    choice = choose_hypotheses(errors, shading.samples.pixel_uv.numpy(), size, config.metal_search_sigma, config.metal_search_margin)
    picked = torch.from_numpy(choice.choice.astype(np.int64))[..., None]

    def pick(name: str) -> torch.Tensor:
        parts = [getattr(fits[k], name) for k in (AS_FITTED, DIELECTRIC, METAL)]
        return torch.where(picked == METAL, parts[METAL], torch.where(picked == DIELECTRIC, parts[DIELECTRIC], parts[AS_FITTED]))

    begin = _Logits(pick("albedo"), pick("roughness"), pick("metallic"))
    return begin, (torch.sigmoid(begin.roughness), torch.sigmoid(begin.metallic)), choice, steps, False


def fit_textures_to_photos(uv_mesh: UVMesh, textures: BakedTextures, photos: PhotoViews, lighting, context,
                           config: TextureFitConfig = TextureFitConfig(), progress: Progress | None = None,
                           should_stop: Callable[[], bool] | None = None) -> tuple[BakedTextures, TextureFitReport]:
    """Rasterise the export from the photos' cameras (through `context`) and fit its textures to them."""
    samples = sample_photo_pixels(mesh_for_rendering(uv_mesh, textures), photos, context, config.min_photo_alpha,
                                  config.footprint, with_sources=config.register_grid > 0 or config.register_heights > 0)
    samples = samples.subset(config.max_pixels, config.seed)
    size = textures.covered.shape[0]
    texels_per_pixel = texels_per_photo_pixel(samples.uv, samples.footprint, size)
    fit_size = fit_size_for(texels_per_pixel, size, config.max_texels_per_pixel, config.fit_size)
    if fit_size == size:
        return fit_textures(textures, samples, lighting, config, progress, should_stop, views=len(photos.cameras))
    coarse = averaged_down(textures, fit_size)
    fitted, report = fit_textures(coarse, samples, lighting, config, progress, should_stop, views=len(photos.cameras))
    report.fit_size, report.texels_per_pixel = fit_size, texels_per_pixel
    return carried_up(textures, coarse, fitted, config.dilation), report
