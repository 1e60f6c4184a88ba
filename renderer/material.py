"""glTF 2.0 metallic-roughness material, as plain numpy data (no GL objects).

Textures are uint8 arrays (H, W, C) with row 0 at the top of the image, sampled with glTF texture
coordinates (u right, v down from the top-left corner). Which textures hold sRGB-encoded colour
(base colour, emissive) and which hold linear data (metallic-roughness, normal, occlusion) follows
the glTF specification; the GPU upload decodes sRGB in hardware before filtering.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class PBRMaterial:
    name: str = "material"
    base_color_factor: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)  # linear RGBA
    metallic_factor: float = 1.0  # glTF defaults
    roughness_factor: float = 1.0
    emissive_factor: tuple[float, float, float] = (0.0, 0.0, 0.0)  # linear RGB
    normal_scale: float = 1.0
    occlusion_strength: float = 1.0
    base_color_texture: np.ndarray | None = None  # sRGB, RGB or RGBA uint8
    metallic_roughness_texture: np.ndarray | None = None  # linear; G = roughness, B = metallic
    normal_texture: np.ndarray | None = None  # linear; tangent-space normal in [0, 1]
    occlusion_texture: np.ndarray | None = None  # linear; R = ambient occlusion
    emissive_texture: np.ndarray | None = None  # sRGB
    double_sided: bool = False
    alpha_mode: str = "OPAQUE"  # OPAQUE | MASK | BLEND (BLEND is drawn as opaque, see renderer)
    alpha_cutoff: float = 0.5
    # glTF extensions the source asked for that we could not honour; the loader warns about them.
    ignored_extensions: list[str] = field(default_factory=list)

    TEXTURE_SLOTS = (
        "base_color_texture",
        "metallic_roughness_texture",
        "normal_texture",
        "occlusion_texture",
        "emissive_texture",
    )
    SRGB_SLOTS = ("base_color_texture", "emissive_texture")

    def __post_init__(self) -> None:
        for slot in self.TEXTURE_SLOTS:
            tex = getattr(self, slot)
            if tex is None:
                continue
            tex = np.asarray(tex)
            if tex.dtype != np.uint8 or tex.ndim not in (2, 3):
                raise ValueError(f"{self.name}: {slot} must be a uint8 image (H, W[, C]), got {tex.dtype} {tex.shape}")
            if tex.ndim == 2:
                tex = tex[:, :, None]
            setattr(self, slot, np.ascontiguousarray(tex))
        if self.alpha_mode not in ("OPAQUE", "MASK", "BLEND"):
            raise ValueError(f"{self.name}: unknown alpha_mode {self.alpha_mode!r}")
