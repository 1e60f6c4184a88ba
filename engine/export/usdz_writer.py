"""The asset as USDZ (Apple's AR Quick Look, Reality Composer), beside the .glb: the same mesh,
normals, UVs and baked textures, written with Pixar's `usd-core`.

Layout inside the package: `asset.usdc` (Y up, 1 unit = 1 metre when the capture has a real size,
the same numbers as the .glb otherwise) with one Mesh under /Asset and a UsdPreviewSurface material:
diffuseColor from the base-colour texture (sRGB), roughness and metallic from the G and B channels
of the metallic-roughness texture, normal from the tangent-space normal map (raw, scale 2 and bias -1,
OpenGL's +Y convention like glTF's). USD's texture coordinates start at the image's bottom, glTF's
at its top: v is flipped. `check_usdz` runs every validator usd-core registers (UsdValidation: what
`usdchecker` runs, the USDZ package, root-layer, missing-reference and shader-compliance rules
among them; usd-core ships no `usdchecker` executable).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from lirm.engine.errors import LirmUserError
from lirm.engine.io.atomic_files import atomic_write
from lirm.engine.io.images import write_png

from .glb_writer import TexturedMesh, to_gltf_frame


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, Vt
    except ImportError:
        raise LirmUserError("USDZ export needs the usd-core package: `.venv/bin/pip install usd-core` "
                            "(`make setup` installs it)") from None
    return Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, Vt


def write_usdz(path: str | Path, mesh: TexturedMesh, world_transform: np.ndarray | None = None) -> Path:
    path = Path(path)
    if path.suffix.lower() != ".usdz":
        raise LirmUserError(f"{path}: the output must be a .usdz file")
    Gf, Sdf, Usd, UsdGeom, UsdShade, UsdUtils, Vt = _pxr()
    positions, normals, _ = to_gltf_frame(mesh, world_transform)
    with tempfile.TemporaryDirectory(prefix="lirm-usdz-") as tmp:
        folder = Path(tmp)
        textures = {"base_color": mesh.base_color_srgb, "metallic_roughness": mesh.metallic_roughness}
        if mesh.normal_map is not None:
            textures["normal"] = mesh.normal_map
        for name, image in textures.items():
            write_png(folder / f"{name}.png", np.ascontiguousarray(image, np.uint8))
        layer = folder / "asset.usdc"
        stage = Usd.Stage.CreateNew(str(layer))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        root = UsdGeom.Xform.Define(stage, "/Asset")
        stage.SetDefaultPrim(root.GetPrim())
        geometry = UsdGeom.Mesh.Define(stage, "/Asset/" + _identifier(mesh.name))
        geometry.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(positions, np.float32)))
        geometry.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(mesh.faces), 3, np.int32)))
        geometry.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(mesh.faces, np.int32).ravel()))
        geometry.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals, np.float32)))
        geometry.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        geometry.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geometry.CreateDoubleSidedAttr(False)
        lo, hi = positions.min(0), positions.max(0)
        geometry.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo)), Gf.Vec3f(*map(float, hi))]))
        st = np.ascontiguousarray(np.c_[mesh.uvs[:, 0], 1.0 - mesh.uvs[:, 1]], np.float32)
        primvar = UsdGeom.PrimvarsAPI(geometry).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        primvar.Set(Vt.Vec2fArray.FromNumpy(st))
        _material(stage, geometry, "normal" in textures, Sdf, UsdShade)
        stage.GetRootLayer().Save()
        packaged = folder / "asset.usdz"
        if not UsdUtils.CreateNewARKitUsdzPackage(Sdf.AssetPath(str(layer)), str(packaged)):
            raise LirmUserError(f"{path}: usd-core could not package the USDZ")
        data = packaged.read_bytes()
    try:
        return atomic_write(path, lambda tmp_path: tmp_path.write_bytes(data))
    except OSError as err:
        raise LirmUserError(f"cannot write {path} ({err.strerror}); choose a folder you can write to") from None


def _material(stage, geometry, with_normal_map: bool, Sdf, UsdShade) -> None:
    material = UsdShade.Material.Define(stage, "/Asset/Material")
    surface = UsdShade.Shader.Define(stage, "/Asset/Material/PreviewSurface")
    surface.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, "/Asset/Material/TexCoords")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)

    def texture(name: str, file: str, colour_space: str):
        shader = UsdShade.Shader.Define(stage, f"/Asset/Material/{name}")
        shader.CreateIdAttr("UsdUVTexture")
        shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set("./" + file)  # anchored to the layer
        shader.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(colour_space)
        shader.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
        shader.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
        shader.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
        return shader

    base = texture("BaseColor", "base_color.png", "sRGB")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(base.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    orm = texture("MetallicRoughness", "metallic_roughness.png", "raw")
    surface.CreateInput("roughness", Sdf.ValueTypeNames.Float).ConnectToSource(orm.CreateOutput("g", Sdf.ValueTypeNames.Float))
    surface.CreateInput("metallic", Sdf.ValueTypeNames.Float).ConnectToSource(orm.CreateOutput("b", Sdf.ValueTypeNames.Float))
    if with_normal_map:
        normal = texture("Normal", "normal.png", "raw")
        normal.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set((2.0, 2.0, 2.0, 1.0))
        normal.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set((-1.0, -1.0, -1.0, 0.0))
        surface.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(normal.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    surface.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(geometry.GetPrim()).Bind(material)


def _identifier(name: str) -> str:
    cleaned = "".join(c if c.isalnum() or c == "_" else "_" for c in name) or "mesh"
    return cleaned if not cleaned[0].isdigit() else "_" + cleaned


def check_usdz(path: str | Path) -> list[str]:
    """Every validator usd-core registers, on the package: [] when none reports an error or warning."""
    from pxr import Usd, UsdValidation

    _pxr()
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    problems = []
    for error in context.Validate(Usd.Stage.Open(str(path))):
        if error.GetType() in (UsdValidation.ValidationErrorType.Error, UsdValidation.ValidationErrorType.Warn):
            validator = error.GetValidator()
            name = validator.GetMetadata().name if validator else "usd"
            problems.append(f"{name}: {error.GetMessage()}")
    return problems


def read_usdz(path: str | Path) -> dict:
    """What a USDZ holds, read back with usd-core: vertex and face counts and the textures it packs."""
    import zipfile

    _, _, Usd, UsdGeom, _, _, _ = _pxr()
    stage = Usd.Stage.Open(str(path))
    meshes = [UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    vertices = sum(len(m.GetPointsAttr().Get()) for m in meshes)
    faces = sum(len(m.GetFaceVertexCountsAttr().Get()) for m in meshes)
    with zipfile.ZipFile(path) as archive:
        textures = sorted(n for n in archive.namelist() if n.endswith(".png"))
    return {"meshes": len(meshes), "vertices": vertices, "faces": faces, "textures": textures,
            "up_axis": str(UsdGeom.GetStageUpAxis(stage)), "meters_per_unit": UsdGeom.GetStageMetersPerUnit(stage)}
