"""OBJ + MTL + PNG export for tools that want it (the same mesh and textures as the .glb).

The MTL uses the common PBR extension (Pr/Pm/map_Pr/map_Pm/norm, read by Blender and most DCCs) and
map_Kd for the base colour. OBJ is +Y up like glTF, so the same frame conversion applies. Every file
is written atomically; the PNGs are named after the .obj.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write
from lirm.engine.io.images import write_png

from .glb_writer import TexturedMesh, to_gltf_frame


def write_obj(path: str | Path, mesh: TexturedMesh, world_transform: np.ndarray | None = None) -> list[Path]:
    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise LirmUserError(f"{path}: the output must be an .obj file")
    stem = path.stem
    positions, normals, _ = to_gltf_frame(mesh, world_transform)
    textures = {f"{stem}_basecolor.png": mesh.base_color_srgb, f"{stem}_roughness.png": mesh.metallic_roughness[..., 1],
                f"{stem}_metallic.png": mesh.metallic_roughness[..., 2]}
    if mesh.normal_map is not None:
        textures[f"{stem}_normal.png"] = mesh.normal_map
    written = []
    for name, image in textures.items():
        write_png(path.with_name(name), image)
        written.append(path.with_name(name))
    mtl = [f"newmtl {stem}", "Kd 1 1 1", "Pr 1", "Pm 1", f"map_Kd {stem}_basecolor.png",
           f"map_Pr {stem}_roughness.png", f"map_Pm {stem}_metallic.png"]
    if mesh.normal_map is not None:
        mtl.append(f"norm {stem}_normal.png")
    atomic_write(path.with_suffix(".mtl"), lambda tmp: tmp.write_text("\n".join(mtl) + "\n"))
    # OBJ's texture origin is the image's bottom-left: v flips from glTF's top-left.
    uv = np.stack([mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], axis=1)
    lines = [f"mtllib {stem}.mtl", f"o {mesh.name}"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in positions]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in uv]
    lines += [f"vn {x:.5f} {y:.5f} {z:.5f}" for x, y, z in normals]
    lines.append(f"usemtl {stem}")
    lines += [f"f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}" for a, b, c in (mesh.faces.astype(np.int64) + 1)]
    atomic_write(path, lambda tmp: tmp.write_text("\n".join(lines) + "\n"))
    return [path, path.with_suffix(".mtl"), *written]
