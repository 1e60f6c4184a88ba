"""Built-in procedural objects: geometry a renderer and exporter can trust, materials a decoder must
tell apart (albedo, roughness and metallic each with their own pattern), variants by seed."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from lirm.engine.synth.mesh_builders import Profile, lathe
from lirm.engine.synth.procedural_objects import BUILTIN_OBJECTS, make_builtin_object
from lirm.engine.synth.texture_patterns import height_to_normal


@pytest.fixture(scope="module")
def objects() -> dict:
    return {name: make_builtin_object(name, seed=0) for name in BUILTIN_OBJECTS}


def _face_normals(part) -> np.ndarray:
    tri = part.positions.astype(np.float64)[part.indices]
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # length = 2 * area


def _sample_surface(parts, count: int, rng: np.random.Generator):
    """Area-weighted random surface points over all parts: (albedo sRGB, roughness, metallic) there,
    i.e. what a renderer's material buffers would show, ignoring visibility."""
    areas = [0.5 * np.linalg.norm(_face_normals(p), axis=1) for p in parts]
    total = sum(a.sum() for a in areas)
    albedo, rough, metal = [], [], []
    for part, area in zip(parts, areas):
        n = max(1, int(round(count * area.sum() / total)))
        face = rng.choice(len(area), size=n, p=area / area.sum())
        w = rng.dirichlet(np.ones(3), size=n)
        uv = np.einsum("nk,nkd->nd", w, part.uvs[part.indices[face]])
        m = part.material
        h, wd = m.base_color_texture.shape[:2]
        x = np.clip((uv[:, 0] * wd).astype(int), 0, wd - 1)
        y = np.clip((uv[:, 1] * h).astype(int), 0, h - 1)
        albedo.append(m.base_color_texture[y, x, :3] / 255.0 * np.asarray(m.base_color_factor[:3]))
        h, wd = m.metallic_roughness_texture.shape[:2]
        x = np.clip((uv[:, 0] * wd).astype(int), 0, wd - 1)
        y = np.clip((uv[:, 1] * h).astype(int), 0, h - 1)
        mr = m.metallic_roughness_texture[y, x] / 255.0
        rough.append(mr[:, 1] * m.roughness_factor)
        metal.append(mr[:, 2] * m.metallic_factor)
    return np.concatenate(albedo), np.concatenate(rough), np.concatenate(metal)


def test_four_named_objects():
    assert isinstance(BUILTIN_OBJECTS, tuple)
    assert len(BUILTIN_OBJECTS) == 4 and len(set(BUILTIN_OBJECTS)) == 4


def test_unknown_name_lists_the_choices():
    with pytest.raises(ValueError) as err:
        make_builtin_object("teapot")
    for name in BUILTIN_OBJECTS:
        assert name in str(err.value)


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_centred_inside_and_filling_the_unit_sphere(objects, name):
    pts = np.vstack([p.positions for p in objects[name]]).astype(np.float64)
    radius = np.linalg.norm(pts, axis=1).max()
    assert 0.8 <= radius <= 1.0
    centre = 0.5 * (pts.min(0) + pts.max(0))
    assert np.abs(centre).max() < 1e-4
    assert (pts.max(0) - pts.min(0)).min() > 0.5  # a solid object, not a sliver


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_parts_are_closed_with_outward_winding(objects, name):
    for part in objects[name]:
        mesh = trimesh.Trimesh(part.positions, part.indices, process=True)  # merges seams and crease splits
        assert mesh.is_watertight, part.name
        assert mesh.is_winding_consistent, part.name
        tri = part.positions.astype(np.float64)[part.indices]
        signed_volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0
        assert signed_volume > 0, part.name
        assert mesh.volume == pytest.approx(signed_volume, rel=1e-3)


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_vertex_normals_agree_with_faces(objects, name):
    for part in objects[name]:
        fn = _face_normals(part)
        area = np.linalg.norm(fn, axis=1)
        assert (area > 1e-12).all(), f"{part.name}: degenerate triangles"
        vn = part.normals[part.indices].astype(np.float64).sum(1)
        cos = np.einsum("ij,ij->i", fn, vn) / (area * np.linalg.norm(vn, axis=1))
        assert cos.min() > 0.2, part.name
        assert np.allclose(np.linalg.norm(part.normals, axis=1), 1.0, atol=1e-4)


@pytest.mark.parametrize("name", ["vase", "mug", "bottle"])
def test_lathes_split_normals_at_hard_creases(objects, name):
    body = objects[name][0]
    key = np.round(body.positions.astype(np.float64), 5)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    # Vertices sharing a position but with normals far apart: the rim or foot edges.
    order = np.argsort(inverse)
    same = inverse[order][1:] == inverse[order][:-1]
    a, b = order[1:][same], order[:-1][same]
    cos = np.einsum("ij,ij->i", body.normals[a], body.normals[b])
    assert (cos < 0.8).sum() >= 64


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_uvs_textures_and_budget(objects, name):
    parts = objects[name]
    assert sum(len(p.indices) for p in parts) < 60_000
    for part in parts:
        uv = part.uvs.astype(np.float64)
        assert np.isfinite(uv).all() and uv.min() >= 0.0 and uv.max() <= 1.0
        t = uv[part.indices]
        e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        uv_area = e1[:, 0] * e2[:, 1] - e2[:, 0] * e1[:, 1]
        assert (np.abs(uv_area) > 1e-12).all(), f"{part.name}: degenerate UV triangles"
        # One UV orientation per part: a mirrored island would flip its tangent frames.
        assert (uv_area > 0).all() or (uv_area < 0).all(), part.name
        m = part.material
        for slot in ("base_color_texture", "metallic_roughness_texture", "normal_texture"):
            tex = getattr(m, slot)
            if tex is None:
                continue
            assert tex.dtype == np.uint8 and tex.shape[2] == 3
            assert 512 <= min(tex.shape[:2]) and max(tex.shape[:2]) <= 1024, (part.name, slot, tex.shape)
        assert m.base_color_texture is not None and m.metallic_roughness_texture is not None
        if m.normal_texture is not None:
            assert part.tangents is not None and np.isfinite(part.tangents).all()


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_albedo_roughness_metallic_each_vary_with_their_own_pattern(objects, name):
    albedo, rough, metal = _sample_surface(objects[name], 40_000, np.random.default_rng(0))
    luminance = albedo @ np.array([0.2126, 0.7152, 0.0722])
    assert np.ptp(albedo, axis=0).max() > 0.3 and luminance.std() > 0.05
    assert rough.std() > 0.05 and np.ptp(rough) > 0.3
    metallic_share = (metal > 0.5).mean()
    assert 0.01 < metallic_share < 0.7
    assert ((metal > 0.05) & (metal < 0.95)).mean() < 0.05  # metal or not, only edges in between
    assert abs(np.corrcoef(rough, metal)[0, 1]) < 0.8
    assert abs(np.corrcoef(rough, luminance)[0, 1]) < 0.9
    assert abs(np.corrcoef(metal, luminance)[0, 1]) < 0.9


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_each_object_has_a_relief_normal_map_somewhere_sensible(objects, name):
    for part in objects[name]:
        nt = part.material.normal_texture
        if nt is None:
            continue
        n = nt.astype(np.float64) / 255.0 * 2.0 - 1.0
        assert n[..., 2].min() > 0.2  # never tilted past grazing
        assert np.abs(np.linalg.norm(n, axis=-1) - 1.0).max() < 0.02
        assert (n[..., 2] < 0.98).mean() > 0.001  # some actual relief
    if name in ("vase", "toy_block", "bottle"):
        assert any(p.material.normal_texture is not None for p in objects[name])


@pytest.mark.parametrize("name", BUILTIN_OBJECTS)
def test_deterministic_by_seed_and_different_across_seeds(objects, name):
    a = make_builtin_object(name, seed=0)
    b = objects[name]
    c = make_builtin_object(name, seed=1)
    for pa, pb in zip(a, b):
        assert np.array_equal(pa.positions, pb.positions)
        assert np.array_equal(pa.material.base_color_texture, pb.material.base_color_texture)
        assert np.array_equal(pa.material.metallic_roughness_texture, pb.material.metallic_roughness_texture)
    assert [p.name for p in a] == [p.name for p in c]
    assert not np.array_equal(a[0].material.base_color_texture, c[0].material.base_color_texture)
    assert not np.array_equal(a[0].material.metallic_roughness_texture, c[0].material.metallic_roughness_texture)
    size_a = np.ptp(np.vstack([p.positions for p in a]), axis=0)
    size_c = np.ptp(np.vstack([p.positions for p in c]), axis=0)
    assert np.abs(size_a - size_c).max() > 1e-3  # proportions change too


def test_mug_handle_on_the_right_and_label_on_the_front(objects):
    body, handle = objects["mug"]
    assert handle.positions[:, 0].mean() > body.positions[:, 0].mean() + 0.2
    # The label's matte print faces -Y; the back of the body is glossy glaze.
    mid = np.abs(body.positions[:, 2] - np.median(body.positions[:, 2])) < 0.05
    outside = body.normals[:, 2] ** 2 < 0.01
    rough = body.material.metallic_roughness_texture[..., 1] / 255.0
    h, w = rough.shape

    def roughness_where(sel):
        uv = body.uvs[sel]
        return rough[(uv[:, 1] * h).astype(int).clip(0, h - 1), (uv[:, 0] * w).astype(int).clip(0, w - 1)].mean()

    front = mid & outside & (body.normals[:, 1] < -0.97)
    back = mid & outside & (body.normals[:, 1] > 0.97)
    assert front.any() and back.any()
    assert roughness_where(front) > roughness_where(back) + 0.2


def test_mug_handle_ends_stay_inside_the_wall_not_the_cavity():
    for seed in range(4):
        body, handle = make_builtin_object("mug", seed)
        axis = 0.5 * (body.positions.min(0) + body.positions.max(0))[:2]
        radial = body.positions[:, :2] - axis
        # Inner wall: vertices whose normals point toward the axis.
        inner = np.einsum("ij,ij->i", body.normals[:, :2], radial) < -0.01
        z, r = body.positions[inner, 2], np.linalg.norm(radial[inner], axis=1)
        order = np.argsort(z)
        r_inner = np.interp(handle.positions[:, 2], z[order], r[order])
        r_handle = np.linalg.norm(handle.positions[:, :2] - axis, axis=1)
        assert (r_handle - r_inner).min() > 0.005, seed


def test_lathe_puts_u_half_at_the_front_and_u_growing_to_the_right():
    p = Profile(0.0, 0.0, "bottom").line_to(1.0, 0.0).corner()
    p.section("side").line_to(1.0, 1.0, steps=2).corner()
    p.section("top").line_to(0.0, 1.0)
    geo, layout = lathe(p, segments=16)
    ring = (np.abs(geo.positions[:, 2] - 0.5) < 1e-9) & (np.abs(geo.normals[:, 2]) < 1e-9)
    pos, uv = geo.positions[ring], geo.uvs[ring]
    front = pos[np.argmin(np.abs(uv[:, 0] - 0.5))]
    assert np.allclose(front, [0.0, -1.0, 0.5], atol=1e-9)
    after = pos[np.argmin(np.abs(uv[:, 0] - 0.5 - 1 / 16))]
    assert after[0] > 0  # seen from the front (camera at -Y, +Z up), +X is to the right
    # Hard corners: the rim vertices carry the cap's normal and the side's normal separately.
    rim = np.abs(geo.positions[:, 2] - 1.0) < 1e-9
    rim &= np.abs(np.linalg.norm(geo.positions[:, :2], axis=1) - 1.0) < 1e-9
    normals = np.round(geo.normals[rim, 2], 6)
    assert set(normals.tolist()) == {0.0, 1.0}
    assert layout.section_names == ("bottom", "side", "top")
    mesh = trimesh.Trimesh(geo.positions, geo.indices)
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(0.5 * 16 * np.sin(2 * np.pi / 16), rel=1e-6)  # the inscribed 16-gon prism


def test_height_to_normal_uses_gltf_green_up():
    rows = np.arange(64, dtype=np.float32)
    rising_to_top = np.repeat((63 - rows)[:, None], 64, axis=1) * 0.1  # row 0 is the image top
    n = height_to_normal(rising_to_top).astype(np.float64) / 255.0 * 2 - 1
    assert n[32, 32, 1] < -0.05  # a slope rising toward the top faces down the image (-Y)
    assert abs(n[32, 32, 0]) < 0.01
    rising_to_right = np.repeat(rows[None, :], 64, axis=0) * 0.1
    n = height_to_normal(rising_to_right).astype(np.float64) / 255.0 * 2 - 1
    assert n[32, 32, 0] < -0.05 and abs(n[32, 32, 1]) < 0.01
