"""Load glTF 2.0 (.gltf, .glb) and OBJ models into the renderer's MeshData, in our +Z-up world.

trimesh gives the geometry, the scene graph and the decoded texture images. It drops or quantises
the rest (float factors, normal scale, occlusion strength, alpha cutoff, extensions, TANGENT,
COLOR_0), so for glTF each trimesh geometry is matched to its source primitive (identical POSITION
data) and those come from the raw file through `gltf_document`.

Axes: glTF is +Y up with the model's front facing +Z; our world is +Z up (DESIGN.md §3). Every
model is rotated +90° about X, (x, y, z) -> (x, -z, y), so the front ends up facing -Y. OBJ declares
no axes; +Y up is the common convention (Blender's, Maya's and most scanners' OBJ export default),
so OBJ gets the same rotation.

UVs follow glTF (v down from the image top). trimesh stores v bottom-up (it flips glTF's v on load,
and OBJ's vt is bottom-up already), so v from trimesh becomes 1 - v.
"""

from __future__ import annotations

import logging
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from lirm.engine.errors import AssetLoadError
from lirm.renderer.material import PBRMaterial
from lirm.renderer.mesh import MeshData
from lirm.renderer.tonemap import srgb_to_linear

from .gltf_document import GltfDocument, read_gltf

log = logging.getLogger("lirm")

SUPPORTED_SUFFIXES = (".gltf", ".glb", ".obj")
# glTF extensions we honour; anything else required is an error, anything else used a warning.
SUPPORTED_EXTENSIONS = frozenset({"KHR_materials_emissive_strength"})

Y_UP_TO_Z_UP = np.array(
    [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)

_GL_TRIANGLES, _GL_TRIANGLE_STRIP = 4, 5

# (our slot, path in the glTF material, trimesh PBRMaterial attribute, words for messages)
_TEXTURE_SLOTS = (
    ("base_color_texture", ("pbrMetallicRoughness", "baseColorTexture"), "baseColorTexture", "base colour"),
    (
        "metallic_roughness_texture",
        ("pbrMetallicRoughness", "metallicRoughnessTexture"),
        "metallicRoughnessTexture",
        "metallic-roughness",
    ),
    ("normal_texture", ("normalTexture",), "normalTexture", "normal"),
    ("occlusion_texture", ("occlusionTexture",), "occlusionTexture", "occlusion"),
    ("emissive_texture", ("emissiveTexture",), "emissiveTexture", "emissive"),
)


@dataclass
class LoadedModel:
    meshes: list[MeshData]
    warnings: list[str] = field(default_factory=list)
    source: Path = field(default_factory=Path)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned min and max corner over all meshes, in world space (+Z up)."""
        corners = np.stack([m.bounds for m in self.meshes])
        return np.stack([corners[:, 0].min(axis=0), corners[:, 1].max(axis=0)])


def load_model(path: str | Path) -> LoadedModel:
    """Load a .gltf, .glb or .obj file. Raises AssetLoadError for anything a user must fix."""
    path = Path(path).expanduser()
    if path.suffix.lower() not in SUPPORTED_SUFFIXES:
        raise AssetLoadError(
            f"{path}: unsupported model format '{path.suffix or '(no extension)'}'; supported formats are "
            f"{', '.join(SUPPORTED_SUFFIXES)} (convert the model to glTF, e.g. with Blender)"
        )
    if not path.is_file():
        raise AssetLoadError(f"{path}: file not found; check the path")
    warnings: list[str] = []
    try:
        meshes = _load_obj(path, warnings) if path.suffix.lower() == ".obj" else _load_gltf(path, warnings)
    except (KeyError, IndexError, TypeError, AttributeError, ValueError, RecursionError) as err:
        # A JSON value of the wrong kind somewhere we read it: the file is at fault, not the user.
        raise AssetLoadError(
            f"{path}: the file is malformed ({type(err).__name__}: {err}); export it again "
            "(for glTF, the Khronos glTF validator names the problem)"
        ) from err
    if not meshes:
        raise AssetLoadError(
            f"{path}: the model contains no triangles (only points, lines or nothing); "
            "export the object's surface as a triangle mesh"
        )
    for message in warnings:
        log.warning(message)
    return LoadedModel(meshes=meshes, warnings=warnings, source=path)


# ---------------------------------------------------------------------------------------- glTF


def _load_gltf(path: Path, warnings: list[str]) -> list[MeshData]:
    doc = read_gltf(path)
    _reject_unsupported(doc)
    _warn_unsupported_features(doc, warnings)
    ignored = _ignored_extensions(doc, warnings)
    scene = _trimesh_scene(path)
    matcher = _PrimitiveMatcher(doc)
    materials = _GltfMaterials(doc, ignored, warnings)
    meshes = []
    for name, matrix, geometry_name, geom in _instances(scene):
        prim = matcher.match(geometry_name, geom)
        if prim is None:
            warnings.append(
                f"{path.name}: mesh '{geometry_name}' could not be matched to its glTF primitive; "
                "it is loaded without tangents and vertex colours, with trimesh's material"
            )
            material = _material_from_trimesh(getattr(geom.visual, "material", None), materials.image_cache)
            normals, uvs = geom.vertex_normals, _uvs_from_trimesh(geom)
            mesh = _build_mesh(path, name, matrix, geom, material, warnings, normals=normals, uvs=uvs)
        else:
            attrs = prim.get("attributes", {})
            material = materials.get(prim.get("material"), getattr(geom.visual, "material", None))
            count = len(geom.vertices)
            normals = _attribute(doc, attrs, "NORMAL", count, (3,), warnings, name)
            uvs = _attribute(doc, attrs, "TEXCOORD_0", count, (2,), warnings, name)
            tangents = _attribute(doc, attrs, "TANGENT", count, (4,), warnings, name)
            colors = _attribute(doc, attrs, "COLOR_0", count, (3, 4), warnings, name, normalize=True)
            if colors is not None and colors.shape[1] == 3:
                colors = np.concatenate([colors, np.ones((count, 1), colors.dtype)], axis=1)
            # glTF says a primitive without NORMAL is shaded flat, not smooth.
            mesh = _build_mesh(
                path, name, matrix, geom, material, warnings,
                normals=normals, uvs=uvs, tangents=tangents, colors=colors, flat=normals is None,
            )  # fmt: skip
        if mesh is not None:
            meshes.append(mesh)
    return meshes


def _reject_unsupported(doc: GltfDocument) -> None:
    required = [e for e in doc.extensions_required if e not in SUPPORTED_EXTENSIONS]
    if required:
        them = "it" if len(required) == 1 else "them"
        raise AssetLoadError(
            f"{doc.path}: the model requires the glTF extension{'s' if len(required) > 1 else ''} "
            f"{', '.join(required)}, which LIRM Studio does not support; re-export the model without "
            f"{them} (e.g. turn off mesh/texture compression in the exporter)"
        )
    accessors = doc.json.get("accessors", [])
    for mesh in doc.json.get("meshes", []):
        for prim in mesh.get("primitives", []):
            used = list(prim.get("attributes", {}).values()) + [prim.get("indices")]
            for index in used:
                # trimesh ignores sparse substitution, so its geometry would silently be wrong.
                if isinstance(index, int) and 0 <= index < len(accessors) and "sparse" in accessors[index]:
                    raise AssetLoadError(
                        f"{doc.path}: mesh '{mesh.get('name', '')}' uses a sparse accessor, which is not "
                        "supported; re-export the model without sparse accessors"
                    )


def _warn_unsupported_features(doc: GltfDocument, warnings: list[str]) -> None:
    name = doc.path.name
    prims = [prim for mesh in doc.json.get("meshes", []) for prim in mesh.get("primitives", [])]
    skipped = sum(prim.get("mode", _GL_TRIANGLES) not in (_GL_TRIANGLES, _GL_TRIANGLE_STRIP) for prim in prims)
    if 0 < skipped < len(prims):  # with nothing left, load_model's "no triangles" error says it
        warnings.append(f"{name}: {skipped} primitive(s) of points, lines or triangle fans are not rendered")
    if doc.json.get("skins"):
        warnings.append(f"{name}: skinning is ignored; the model is shown without its skeleton's pose")
    if any("targets" in prim for prim in prims):
        warnings.append(f"{name}: morph targets are ignored; the model is shown in its base shape")


def _ignored_extensions(doc: GltfDocument, warnings: list[str]) -> dict[int, list[str]]:
    """Warn once per unsupported extension; return the ones each material loses, by material index."""
    materials = doc.json.get("materials", [])
    per_material = [_extension_names(m) for m in materials]
    names = list(dict.fromkeys(doc.extensions_used + sorted(set().union(*per_material))))
    ignored: dict[int, list[str]] = defaultdict(list)
    for ext in names:
        if ext in SUPPORTED_EXTENSIONS:
            continue
        affected = [i for i, found in enumerate(per_material) if ext in found]
        if affected:
            labels = ", ".join(f"'{_material_name(materials[i], i)}'" for i in affected)
            warnings.append(
                f"{doc.path.name}: glTF extension {ext} is not supported; material(s) {labels} are rendered "
                "with their base metallic-roughness layer only"
            )
        else:
            warnings.append(f"{doc.path.name}: glTF extension {ext} is not supported and is ignored")
        for i in affected:
            ignored[i].append(ext)
    return ignored


def _extension_names(obj) -> set[str]:
    """Names of all extensions anywhere inside a glTF object (material or texture infos)."""
    found: set[str] = set()
    if isinstance(obj, dict):
        for key, value in obj.items():
            if key == "extensions" and isinstance(value, dict):
                found.update(value)
            found |= _extension_names(value)
    elif isinstance(obj, list):
        for value in obj:
            found |= _extension_names(value)
    return found


def _material_name(spec: dict, index: int) -> str:
    return spec.get("name") or f"material {index}"


class _PrimitiveMatcher:
    """Finds the glTF primitive a trimesh geometry came from, by identical POSITION (and index) data.

    trimesh keys geometries by uniquified mesh names and keeps no primitive index, so comparing the
    data is the one link that survives trimesh versions.
    """

    def __init__(self, doc: GltfDocument):
        self.doc = doc
        self.by_positions: dict[bytes, list[dict]] = defaultdict(list)
        keys: dict[int, bytes] = {}
        for mesh in doc.json.get("meshes", []):
            for prim in mesh.get("primitives", []):
                acc = prim.get("attributes", {}).get("POSITION")
                if acc is None or prim.get("mode", _GL_TRIANGLES) not in (_GL_TRIANGLES, _GL_TRIANGLE_STRIP):
                    continue
                if acc not in keys:
                    keys[acc] = _array_key(doc.accessor(acc))
                self.by_positions[keys[acc]].append(prim)
        self.used: set[int] = set()
        self.by_geometry: dict[str, dict | None] = {}

    def match(self, geometry_name: str, geom: trimesh.Trimesh) -> dict | None:
        if geometry_name not in self.by_geometry:
            candidates = self.by_positions.get(_array_key(geom.vertices), [])
            if len(candidates) > 1:  # primitives sharing one vertex buffer: tell them apart by faces
                candidates = [p for p in candidates if self._same_faces(p, geom.faces)] or candidates
            fresh = [p for p in candidates if id(p) not in self.used]
            prim = (fresh or candidates or [None])[0]
            if prim is not None:
                self.used.add(id(prim))
            self.by_geometry[geometry_name] = prim
        return self.by_geometry[geometry_name]

    def _same_faces(self, prim: dict, faces: np.ndarray) -> bool:
        if prim.get("mode", _GL_TRIANGLES) != _GL_TRIANGLES:
            return True
        if "indices" in prim:
            ours = self.doc.accessor(prim["indices"]).reshape(-1, 3)
        else:
            ours = np.arange(len(faces) * 3).reshape(-1, 3)
        return ours.shape == faces.shape and np.array_equal(ours, faces)


def _array_key(positions: np.ndarray) -> bytes:
    # trimesh widens float32 POSITION to float64 exactly, so float32 bytes compare equal.
    return np.ascontiguousarray(positions, dtype=np.float32).tobytes()


def _attribute(
    doc: GltfDocument,
    attrs: dict,
    semantic: str,
    count: int,
    widths: tuple[int, ...],
    warnings: list[str],
    mesh_name: str,
    normalize: bool | None = None,
) -> np.ndarray | None:
    if semantic not in attrs:
        return None
    data = doc.accessor(attrs[semantic], normalize=normalize)
    if data.ndim != 2 or data.shape[0] != count or data.shape[1] not in widths:
        warnings.append(f"{doc.path.name}: mesh '{mesh_name}' has a malformed {semantic} attribute; it is ignored")
        return None
    return data.astype(np.float32)


class _GltfMaterials:
    """PBRMaterials from the glTF JSON (parameters) and trimesh (decoded images), one per material index."""

    def __init__(self, doc: GltfDocument, ignored: dict[int, list[str]], warnings: list[str]):
        self.doc = doc
        self.ignored = ignored
        self.warnings = warnings
        self.missing_images = doc.missing_images()
        self.image_cache: dict = {}
        self.built: dict[int | None, PBRMaterial] = {None: PBRMaterial(name="default")}  # glTF's default material

    def get(self, index: int | None, tm_material) -> PBRMaterial:
        if index not in self.built:
            self.built[index] = self._build(index, tm_material)
        return self.built[index]

    def _build(self, index: int, tm_material) -> PBRMaterial:
        doc = self.doc
        materials = doc.json.get("materials", [])
        if not isinstance(index, int) or not 0 <= index < len(materials):
            raise AssetLoadError(
                f"{doc.path}: a primitive uses material {index!r}, which does not exist; export the model again"
            )
        spec = materials[index]
        name = _material_name(spec, index)
        try:
            params = _material_factors(spec)
        except (TypeError, ValueError, AttributeError) as err:
            raise AssetLoadError(
                f"{doc.path}: material '{name}' has an invalid value ({err}); export the model again"
            ) from None
        if params["alpha_mode"] not in ("OPAQUE", "MASK", "BLEND"):
            self.warnings.append(
                f"{doc.path.name}: material '{name}' has unknown alphaMode {params['alpha_mode']!r}; drawn opaque"
            )
            params["alpha_mode"] = "OPAQUE"
        for slot, keys, tm_attr, label in _TEXTURE_SLOTS:
            info = spec
            for key in keys:
                info = info.get(key) or {}
            if not info:
                continue
            where = f"the {label} texture of material '{name}'"
            image = self._texture(info, getattr(tm_material, tm_attr, None), slot, where)
            if image is not None:
                params[slot] = image
            elif slot == "emissive_texture":
                # The factor multiplies the texture: without it, DamagedHelmet's (1, 1, 1) would glow all over.
                params["emissive_factor"] = (0.0, 0.0, 0.0)
        return PBRMaterial(name=name, ignored_extensions=list(self.ignored.get(index, [])), **params)

    def _texture(self, info: dict, tm_image, slot: str, where: str) -> np.ndarray | None:
        doc = self.doc
        textures = doc.json.get("textures", [])
        tex_index = info.get("index")
        valid = isinstance(tex_index, int) and 0 <= tex_index < len(textures)
        source = textures[tex_index].get("source") if valid else None
        if source in self.missing_images:
            self.warnings.append(
                f"{doc.path.name}: texture file '{doc.image_uris[source]}' ({where}) was not found next to the "
                "model; loading without it"
            )
            return None
        if info.get("texCoord", 0) != 0:
            self.warnings.append(
                f"{doc.path.name}: {where} uses TEXCOORD_{info['texCoord']}; only TEXCOORD_0 is supported, "
                "loading without it"
            )
            return None
        image = _image_array(tm_image, slot == "base_color_texture", self.image_cache)
        if image is None:
            self.warnings.append(f"{doc.path.name}: {where} could not be decoded; loading without it")
        return image


def _material_factors(spec: dict) -> dict:
    """The scalar parameters of a glTF material, with the specification's defaults."""
    pbr = spec.get("pbrMetallicRoughness", {})
    strength = spec.get("extensions", {}).get("KHR_materials_emissive_strength", {}).get("emissiveStrength", 1.0)
    return dict(
        base_color_factor=_floats(pbr.get("baseColorFactor", (1.0, 1.0, 1.0, 1.0)), 4),
        metallic_factor=float(pbr.get("metallicFactor", 1.0)),
        roughness_factor=float(pbr.get("roughnessFactor", 1.0)),
        emissive_factor=tuple(float(strength) * e for e in _floats(spec.get("emissiveFactor", (0.0, 0.0, 0.0)), 3)),
        normal_scale=float(spec.get("normalTexture", {}).get("scale", 1.0)),
        occlusion_strength=float(spec.get("occlusionTexture", {}).get("strength", 1.0)),
        double_sided=bool(spec.get("doubleSided", False)),
        alpha_mode=str(spec.get("alphaMode", "OPAQUE")),
        alpha_cutoff=float(spec.get("alphaCutoff", 0.5)),
    )


def _floats(values, n: int) -> tuple[float, ...]:
    values = tuple(float(v) for v in values)
    if len(values) != n:
        raise ValueError(f"expected {n} numbers, got {len(values)}")
    return values


# ----------------------------------------------------------------------------------------- OBJ


def _load_obj(path: Path, warnings: list[str]) -> list[MeshData]:
    _warn_missing_obj_files(path, warnings)
    scene = _trimesh_scene(path)
    materials: dict[int, PBRMaterial] = {}
    image_cache: dict = {}
    meshes = []
    for name, matrix, _, geom in _instances(scene):
        visual = geom.visual
        colors = None
        tm_material = getattr(visual, "material", None)
        if tm_material is not None:
            if id(tm_material) not in materials:
                materials[id(tm_material)] = _material_from_trimesh(tm_material, image_cache)
            material = materials[id(tm_material)]
        else:
            material = _obj_default_material()
            if getattr(visual, "kind", None) == "vertex":
                # OBJ vertex colours are display colours (sRGB); MeshData wants linear.
                rgba = np.asarray(visual.vertex_colors, np.float32) / 255.0
                colors = np.concatenate([srgb_to_linear(rgba[:, :3]).astype(np.float32), rgba[:, 3:]], axis=1)
        mesh = _build_mesh(
            path, name, matrix, geom, material, warnings,
            normals=geom.vertex_normals, uvs=_uvs_from_trimesh(geom), colors=colors,
        )  # fmt: skip
        if mesh is not None:
            meshes.append(mesh)
    return meshes


def _obj_default_material() -> PBRMaterial:
    # glTF's defaults (white metal) would look like a mirror; an untextured OBJ means grey plastic.
    return PBRMaterial(
        name="default", base_color_factor=(0.8, 0.8, 0.8, 1.0), metallic_factor=0.0, roughness_factor=0.5
    )


def _warn_missing_obj_files(path: Path, warnings: list[str]) -> None:
    """trimesh silently falls back to a default material when an MTL or its texture is missing."""
    try:
        with path.open(encoding="utf-8", errors="replace") as f:
            libraries = [line[6:].strip() for line in f if line.startswith("mtllib")]
    except OSError as err:
        raise AssetLoadError(f"{path}: cannot be read ({err.strerror or err})") from None
    for library in filter(None, libraries):
        mtl = path.parent / library
        if not mtl.is_file():
            warnings.append(
                f"{path.name}: material library '{library}' was not found next to the model; default materials are used"
            )
            continue
        try:
            lines = mtl.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError as err:
            warnings.append(f"{path.name}: material library '{library}' cannot be read ({err.strerror or err})")
            continue
        material = "?"
        for line in lines:
            words = line.split()
            if words[:1] == ["newmtl"] and len(words) > 1:
                material = words[1]
            elif words[:1] == ["map_Kd"] and len(words) > 1 and not (mtl.parent / words[-1]).is_file():
                warnings.append(
                    f"{path.name}: texture file '{words[-1]}' (the base colour texture of material '{material}') "
                    "was not found; loading without it"
                )


# ------------------------------------------------------------------------------- shared pieces


def _trimesh_scene(path: Path) -> trimesh.Scene:
    try:
        # allow_anywhere: trimesh otherwise refuses '../textures/x.png' URIs and symlinked files
        # that resolve outside the model's folder, both ordinary on a user's own disk.
        resolver = trimesh.resolvers.FilePathResolver(path, allow_anywhere=True)
        return trimesh.load(path, force="scene", process=False, resolver=resolver)
    except Exception as err:  # trimesh raises anything from ValueError to ModuleNotFoundError on bad input
        raise AssetLoadError(
            f"{path}: the model could not be read ({type(err).__name__}: {err}); "
            "the file may be corrupt, export it again"
        ) from err


def _instances(scene: trimesh.Scene):
    """(name, world matrix in +Z up, geometry name, triangle mesh) for every placed triangle mesh."""
    nodes = [n for n in scene.graph.nodes_geometry if _is_triangle_mesh(scene.geometry.get(scene.graph[n][1]))]
    uses = Counter(scene.graph[n][1] for n in nodes)
    for node in nodes:
        matrix, geometry_name = scene.graph[node]
        name = geometry_name if uses[geometry_name] == 1 else f"{geometry_name} [{node}]"
        yield name, Y_UP_TO_Z_UP @ np.asarray(matrix, np.float64), geometry_name, scene.geometry[geometry_name]


def _is_triangle_mesh(geom) -> bool:
    return isinstance(geom, trimesh.Trimesh) and len(geom.faces) > 0


def _uvs_from_trimesh(geom: trimesh.Trimesh) -> np.ndarray | None:
    uv = getattr(geom.visual, "uv", None)
    if uv is None or len(uv) != len(geom.vertices):
        return None
    uv = np.array(uv[:, :2], dtype=np.float64)
    uv[:, 1] = 1.0 - uv[:, 1]  # trimesh's bottom-up v -> glTF's top-down v
    return uv


def _build_mesh(
    path: Path,
    name: str,
    matrix: np.ndarray,
    geom: trimesh.Trimesh,
    material: PBRMaterial,
    warnings: list[str],
    *,
    normals: np.ndarray | None = None,
    uvs: np.ndarray | None = None,
    tangents: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    flat: bool = False,
) -> MeshData | None:
    """MeshData for one placed geometry: world transform applied, attributes checked."""
    positions = np.asarray(geom.vertices, np.float64)
    faces = np.asarray(geom.faces, np.int64)
    if not np.isfinite(positions).all():
        raise AssetLoadError(
            f"{path}: mesh '{name}' has NaN or infinite vertex positions; the file is corrupt, export it again"
        )
    if len(faces) and (faces.min() < 0 or faces.max() >= len(positions)):
        raise AssetLoadError(
            f"{path}: mesh '{name}' has face indices out of range; the file is corrupt, export it again"
        )
    attributes = {"normals": normals, "uvs": uvs, "tangents": tangents, "colors": colors}
    for key, value in attributes.items():
        if value is not None and not np.isfinite(value).all():
            warnings.append(f"{path.name}: mesh '{name}' has NaN or infinite {key}; they are ignored")
            attributes[key] = None
    normals, uvs, tangents, colors = attributes.values()
    linear = matrix[:3, :3]
    with np.errstate(invalid="ignore", over="ignore"):
        det = float(np.linalg.det(linear)) if np.isfinite(matrix).all() else float("nan")
    if not np.isfinite(det) or abs(det) < 1e-30:
        warnings.append(f"{path.name}: mesh '{name}' has a zero-scale or invalid node transform and is skipped")
        return None
    positions = positions @ linear.T + matrix[:3, 3]
    if det < 0:
        faces = faces[:, [0, 2, 1]]  # a mirroring transform turns counter-clockwise faces clockwise
    if normals is not None:
        normals = _unit(np.asarray(normals, np.float64) @ np.linalg.inv(linear))  # inverse-transpose
    if tangents is not None:
        xyz = _unit(np.asarray(tangents[:, :3], np.float64) @ linear.T)
        sign = np.where(tangents[:, 3] < 0, -1.0, 1.0) * np.sign(det)  # a mirror flips the bitangent
        tangents = np.concatenate([xyz, sign[:, None]], axis=1)
    if flat:
        corners = faces.reshape(-1)
        positions = positions[corners]
        uvs, tangents, colors = (None if a is None else a[corners] for a in (uvs, tangents, colors))
        faces = np.arange(len(corners)).reshape(-1, 3)
        tri = positions.reshape(-1, 3, 3)
        face_n = _unit(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
        normals = np.repeat(face_n, 3, axis=0)
    try:
        return MeshData(
            positions=positions, indices=faces, normals=normals, uvs=uvs, tangents=tangents,
            colors=colors, material=material, name=name,
        )  # fmt: skip
    except ValueError as err:
        raise AssetLoadError(f"{path}: {err}; the file is corrupt, export it again") from None


def _unit(v: np.ndarray) -> np.ndarray:
    length = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(length > 1e-20, v / np.maximum(length, 1e-20), np.array([0.0, 0.0, 1.0]))


def _material_from_trimesh(tm_material, image_cache: dict) -> PBRMaterial:
    """OBJ materials, and the fallback when a glTF primitive cannot be matched."""
    if isinstance(tm_material, trimesh.visual.material.SimpleMaterial):
        diffuse = np.asarray(tm_material.diffuse, np.float64).reshape(-1)[:4] / 255.0
        texture = _image_array(tm_material.image, True, image_cache)
        # Exporters write Kd 0.8 beside map_Kd by habit; multiplying would darken every texture.
        base = (1.0, 1.0, 1.0, diffuse[3]) if texture is not None else tuple(diffuse)
        shininess = tm_material.glossiness
        # Blinn-Phong exponent -> GGX roughness, as trimesh's own to_pbr() does.
        roughness = (2.0 / (float(shininess) + 2.0)) ** 0.25 if shininess is not None else 0.5
        return PBRMaterial(
            name=tm_material.name or "material",
            base_color_factor=tuple(float(c) for c in base),
            metallic_factor=0.0,
            roughness_factor=float(np.clip(roughness, 0.0, 1.0)),
            base_color_texture=texture,
        )
    if isinstance(tm_material, trimesh.visual.material.PBRMaterial):
        factor = tm_material.baseColorFactor  # uint8 RGBA in trimesh, None when absent
        base = (1.0, 1.0, 1.0, 1.0) if factor is None else tuple(float(c) / 255.0 for c in np.asarray(factor)[:4])
        emissive = tm_material.emissiveFactor
        params = dict(
            base_color_factor=base,
            metallic_factor=1.0 if tm_material.metallicFactor is None else float(tm_material.metallicFactor),
            roughness_factor=1.0 if tm_material.roughnessFactor is None else float(tm_material.roughnessFactor),
            emissive_factor=(0.0, 0.0, 0.0) if emissive is None else tuple(float(e) for e in emissive),
            double_sided=bool(tm_material.doubleSided),
            alpha_mode=tm_material.alphaMode or "OPAQUE",
            alpha_cutoff=0.5 if tm_material.alphaCutoff is None else float(tm_material.alphaCutoff),
        )
        for slot, _, tm_attr, _ in _TEXTURE_SLOTS:
            params[slot] = _image_array(getattr(tm_material, tm_attr, None), slot == "base_color_texture", image_cache)
        if params["emissive_texture"] is None and emissive is not None and tm_material.emissiveTexture is not None:
            params["emissive_factor"] = (0.0, 0.0, 0.0)
        return PBRMaterial(name=tm_material.name or "material", **params)
    return _obj_default_material()


def _image_array(image, keep_alpha: bool, cache: dict) -> np.ndarray | None:
    """A PIL image as uint8 (H, W, 3), or (H, W, 4) when keep_alpha and it has alpha. None if undecodable."""
    if image is None:
        return None
    key = (id(image), keep_alpha)
    if key not in cache:
        cache[key] = _decode(image, keep_alpha)
    return cache[key]


def _decode(image, keep_alpha: bool) -> np.ndarray | None:
    try:
        mode = image.mode
        if mode.startswith("I") or mode == "F":  # 16/32-bit greyscale: PIL's convert("RGB") clips it
            values = np.asarray(image, dtype=np.float64)
            if mode == "F":
                values = values * 255.0
            elif mode.startswith("I;16") or values.max(initial=0.0) > 255.0:
                values = values / 257.0
            grey = np.clip(np.rint(values), 0, 255).astype(np.uint8)
            return np.repeat(grey[:, :, None], 3, axis=2)
        has_alpha = mode in ("RGBA", "LA", "PA", "RGBa", "La") or "transparency" in image.info
        target = "RGBA" if keep_alpha and has_alpha else "RGB"
        return np.array(image if mode == target else image.convert(target), dtype=np.uint8)
    except (OSError, ValueError, SyntaxError) as err:  # PIL's errors for truncated or unknown images
        log.debug("texture decode failed: %s", err)
        return None

