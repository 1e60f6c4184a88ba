"""Settings of the per-scene refinement, with named presets.

The refinement optimises the project's own field (hexa-plane SDF, PBR heads, NDE radiance) to the
capture's views after the feed-forward pass: the test-time optimisation the paper lists as missing
(its limitations), in the manner of the optimisation-based methods it compares with.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace


CURVATURE_STEP = 0.01  # of the bounding radius: about a pixel's footprint at the protocol's 128 px
# Below this weight a ray sample's colour and materials are not read (ray_rendering.py): a ray's
# left-out weights summed to at most 0.0014 in a refinement of the synthetic vase (measured).
APPEARANCE_WEIGHT = 1e-4


@dataclass(frozen=True)
class LossWeights:
    colour: float = 1.0  # L1 on the radiance over white, against the masked photo
    mask: float = 0.1  # binary cross-entropy of the opacity against the mask
    eikonal: float = 0.05  # (|grad s| - 1)^2 at points near the surface
    curvature: float = 0.2  # 1 - cos between the SDF's normals a short step apart (curvature_step)
    curvature_step: float = CURVATURE_STEP  # that step's spread, in bounding radii
    normal: float = 0.02  # the MLP normal against the SDF's numerical normal (the paper's stage-3 term)
    albedo: float = 0.1  # albedo against the linearised observed colour (stand-in for inverse rendering)
    material_prior: float = 0.01  # roughness toward 0.5 and metallic toward 0 where nothing else says otherwise
    plane_tv: float = 0.0  # total variation of the planes (sparse views at high plane resolution)
    # The soft volume inside the surface, at points spread over the masks' hull: a steady push that
    # the photos and masks resist where they see the surface; where no view does (an object's
    # underside under views from above, a cup's inside under a cap), the smallest solid wins.
    volume: float = 0.0
    # Below the lowest surface the photos see, the SDF at least the height under it (unseen_floor.py):
    # the wedge the masks' hull leaves under an object photographed from above (README: its worth).
    floor: float = 0.5
    # The SDF held positive outside the sampling grid, where no render looks (outside_bounds.py): the
    # shared planes otherwise grow surfaces there, a lid over a carved opening (README, "Empty where the
    # fit never looks"). On with `photo_carving` since stop 79; `lirm refine --no-carve-openings` turns both off.
    outside_bounds: float = 0.5
    # Inverse rendering (with RefineConfig.inverse_rendering and a lighting estimate): the PBR materials
    # shaded under the capture's lighting against the photo, the lighting held to what the photos'
    # backgrounds saw and smooth where they saw nothing.
    pbr: float = 0.5
    albedo_delit: float = 0.0  # the albedo against the photo de-lit in closed form (objective.delit_albedo); off: not worth it yet (README)
    # Nearby rays of one view whose photo colours have the same chromaticity should have the same
    # albedo (objective.paired_albedo_smoothness): their difference in brightness is shading, which the
    # lighting must then explain instead of the albedo (README: what it was worth).
    albedo_pairs: float = 0.0
    # Each surface point's roughness and metallic held to those of the batch's points with a like
    # albedo (shared_materials.py): what a few pixels' highlights say about a paint reaches all of it.
    # The roughness only: sharing the metallic too cost metallic PSNR (thin gold lines, their albedo
    # blurred into the paint around them at 128 px, were pulled to its metallic; README).
    shared_materials: float = 0.5
    share_metallic: bool = False
    shared_albedo_sigma: float = 0.05  # how unlike two albedos may be and still count as one paint (shared_materials.ALBEDO_SIGMA)
    # The part of the log albedo that a linear function of the normal explains (unshaded_albedo.py):
    # shading the inputs were lit with, which the lighting should carry instead. Off: the fit made
    # everything metal instead (README).
    albedo_unshaded: float = 0.0
    # The albedo's L1 difference over a short step on the surface (albedo_smoothness.py): grain the
    # albedo took from a grainy normal goes back to the normal and the light. Off: measured worse (README).
    albedo_smooth: float = 0.0
    # Each surface point's albedo held to the mean albedo of the batch's points with a like albedo
    # (shared_materials.shared_albedo_loss, the same kernel as shared_materials): a paint is one
    # colour, so the slow shading a wrong light leaves in it must go to the light. Off: measured worse
    # on every object, the fit turned the paint metal instead (README, "Three albedo priors").
    shared_albedo: float = 0.0
    # Each ray's metallic, roughness and albedo chromaticity held to what the image-space material
    # network predicts at its pixel (image_materials.py; RefineConfig.material_network says when). On the
    # held-out synthetic sets (the network's own kind of object) the metallic and the albedo's colour held
    # at 0.1 each lift the metallic 13.8 -> 22.9 dB and the relighting 24.75 -> 25.35; on the glTF set,
    # objects unlike any it was trained on, it sees metal on a plain white bunny and the relighting fell
    # 22.26 -> 20.94, which its familiarity check now prevents (README, "The image-space material prior",
    # "Does the network know these photos?"). The roughness stays the photos': held too, with stop 83's network
    # it lifts the roughness over the 8 held-out objects 16.76 -> 17.52 dB but costs the relighting 26.00 -> 25.58
    # (README, "The roughness, held to the network").
    image_metallic: float = 0.1
    image_roughness: float = 0.0
    image_albedo: float = 0.1
    # The roughness held to the network's in proportion to how little the ray's shading changes with it
    # (roughness_observability.py): the network where the photo is silent, the photo where it shows a
    # highlight. Off: over the 8 held-out objects roughness 16.76 -> 17.69 dB, relighting 26.00 -> 25.68
    # (README, "The roughness, held to the network").
    image_roughness_unseen: float = 0.0
    # The sensitivity (display change per unit of roughness) at which that hold is halved: 0.2 is a step of
    # 0.05 in roughness moving the pixel by 0.01 (about 2.5 of 255), near the photos' quantisation and noise.
    unseen_roughness_scale: float = 0.2
    # The albedo's brightness from pixel to pixel held to the network's too, up to one scale for the
    # whole batch (the brightness of the light and of the paint are still the fit's to share): the
    # network has learnt to tell a dark paint from a shadowed side. Since stop 82: over the 8 held-out
    # synthetic objects albedo +1.3 dB, relighting +0.24 (README, "The albedo's shading, from the network").
    image_albedo_shade: float = 0.1
    light_seen: float = 0.2
    light_smooth: float = 0.02
    # The fitted light's colour held neutral where no photo saw it (PanoramaLighting.neutrality_loss).
    # Off: measured worse on three of the four synthetic objects, whose unseen skies are not grey (README).
    light_neutral: float = 0.0

    @property
    def reads_material_network(self) -> bool:
        return bool(self.image_metallic or self.image_roughness or self.image_albedo or self.image_albedo_shade
                    or self.image_roughness_unseen)

    def to_dict(self) -> dict:
        return asdict(self)


MATERIAL_NETWORK_USES = ("auto", "on", "off")


@dataclass(frozen=True)
class RefineConfig:
    minutes: float | None = 3.0  # wall-clock budget of the fit (None: only `iterations` bounds it)
    iterations: int = 100_000  # at most this many optimiser steps
    rays_per_step: int = 2048
    coarse_samples: int = 48  # uniform samples per ray, SDF only and no gradient, to find the surface
    fine_samples: int = 24  # samples per ray drawn around the surface the coarse pass found
    appearance_weight: float = APPEARANCE_WEIGHT  # 0: every sample's colour and materials are read
    plane_resolutions: tuple[int, ...] = (64, 128, 192)  # coarse to fine, switched at equal shares of the budget
    # 1/beta from, to (reached at `beta_ramp` of the budget). It ends sharper than the renderer's 250:
    # at 250 the density reaching a few beta outside the zero level made the fit shrink the surface by
    # about 0.011 R to match the masks (README: what 500 and 1000 were worth).
    inv_beta: tuple[float, float] = (40.0, 500.0)
    beta_ramp: float = 0.6
    plane_lr: float = 2e-2
    nde_lr: float = 1e-2
    head_lr: float = 2e-3
    final_lr_fraction: float = 0.1  # learning rates decay (cosine) to this share at the end of the budget
    edge_ray_fraction: float = 0.25  # share of each batch drawn from pixels along the mask's edge
    # The rest of each batch drawn only from pixels whose ray meets the masks' dilated hull (the
    # others render empty and teach nothing; refine_views.through_grid).
    rays_through_hull: bool = False
    eikonal_points: int = 1024
    hull_resolution: int = 64  # the visual hull of the masks bounds where samples are taken
    hull_dilation_voxels: int = 2  # slack for masks and poses that are not exact (real captures)
    # The hull carved further where the photos see through it (photo_carving.py: a mug's opening, which
    # every mask covers), with the hollow below (hollow_openings). On by default since stop 79: the demo
    # mug comes back open, relit 18.61 -> 18.78 dB, its fitted light's up-plane irradiance 0.63 -> 0.71 x;
    # the held-out sets the same within a run's noise (README, "On by default").
    photo_carving: bool = True
    # With `photo_carving`: an opening whose bottom the photos did not see continued down to a floor
    # a wall's thickness above the lowest surface they saw (unseen_hollow.py: a mug's inside).
    hollow_openings: bool = True
    hull_init_steps: int = 150  # `--init hull`: steps regressing the field to the hull before the photometric fit
    best_every: int = 20  # steps between checks of the running loss for the best state so far
    seed: int = 0
    device: str = "cpu"
    # Inverse rendering: fit the materials (and the lighting, from the capture's estimate) through the
    # renderer's split-sum shading, from `pbr_start` of the budget on (the shape settles first).
    inverse_rendering: bool = False
    pbr_start: float = 0.1
    # The normal the PBR term shades with: "head", the field's predicted normal, or "sdf", the SDF's
    # gradient at each ray's surface point: the normal the export's normal map stores (README: what each was worth);
    # "sdf-fixed", the same normal without letting the shading move the surface.
    shading_normal: str = "sdf"
    # With an SDF shading normal: the PBR term's lobe widened by the spread of the surface's normal over
    # each pixel (footprint_roughness.py), so that a thin rim need not be fitted rough to look as
    # blurred as its photo. (README: what it was worth.)
    footprint_roughness: bool = False
    # The floor term (losses.floor) from this share of the budget on; its height is followed from the start.
    floor_start: float = 0.2
    # The albedo smoothness term's pairs: this share of each batch's uniform rays comes as neighbours of
    # the others, within `pair_radius_px` pixels in the same view (no extra rays are rendered).
    pair_fraction: float = 0.25
    pair_radius_px: int = 3
    lighting_lr: float = 3e-2
    lighting_height: int = 16  # the fitted panorama's rows (x 2 columns)
    lighting_sharpest_lobe: float = 1.0  # the narrowest specular lobe of the fitted panorama, in texels
    # Compact lights fitted beside the panorama (panorama_lighting.py: spherical Gaussians outside its
    # smoothness term), for a sun or lamp no photo saw. One since 2026-12-02: at equal steps it relit
    # both held-out sets a little better and placed the demo's sun better (README, "Compact lights").
    light_lobes: int = 1
    # The smoothness term's heavy tail (panorama_lighting.smoothness_loss): 0, plain total variation.
    lighting_smooth_scale: float = 0.25
    # The material prior holds roughness and metallic to the starting field's where that is a
    # prediction (LIRM, an earlier refinement) rather than to 0.5 and 0 (README: what it was worth).
    anchor_materials: bool = True
    # The image-space material network the image_materials / image_albedo terms read ("": the shipped one).
    material_net: str = ""
    # When the fit listens to it: "auto" only on photos it knows (model/material_net_familiarity.py: its
    # metal stable under a mirror flip and the training's exposure range), "on" always, "off" never.
    material_network: str = "auto"
    losses: LossWeights = field(default_factory=LossWeights)

    def __post_init__(self) -> None:
        if self.minutes is not None and not self.minutes > 0:
            raise ValueError(f"the time budget must be positive, got {self.minutes} minutes")
        if self.iterations < 1:
            raise ValueError(f"iterations must be at least 1, got {self.iterations}")
        if self.material_network not in MATERIAL_NETWORK_USES:
            raise ValueError(f"material_network must be one of {', '.join(MATERIAL_NETWORK_USES)}, got {self.material_network!r}")
        if self.rays_per_step < 16:
            raise ValueError(f"rays per step must be at least 16, got {self.rays_per_step}")
        if not self.plane_resolutions or min(self.plane_resolutions) < 8 or max(self.plane_resolutions) > 1024:
            raise ValueError(f"plane resolutions must lie in 8..1024, got {self.plane_resolutions}")
        if self.shading_normal not in ("head", "sdf", "sdf-fixed"):
            raise ValueError(f"the shading normal is 'head', 'sdf' or 'sdf-fixed', got {self.shading_normal!r}")

    def to_dict(self) -> dict:
        return asdict(self)


PRESETS: dict[str, RefineConfig] = {
    # The default: a 3-minute fit on a 2-core CPU (the goal for 16 views at 128 px).
    "default": RefineConfig(),
    # A quick look (tests, the app's first pass): one minute, lower plane resolution.
    "fast": RefineConfig(minutes=1.0, plane_resolutions=(64, 128)),
    # Longer fits get finer planes.
    "quality": RefineConfig(minutes=10.0, plane_resolutions=(64, 128, 256), rays_per_step=4096),
}


def refine_preset(name: str, **overrides) -> RefineConfig:
    if name not in PRESETS:
        raise ValueError(f"unknown refinement preset {name!r}; choose one of: {', '.join(PRESETS)}")
    return replace(PRESETS[name], **overrides)
