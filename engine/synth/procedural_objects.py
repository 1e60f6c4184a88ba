"""Built-in procedural objects with spatially varying glTF metallic-roughness materials.

Used by `lirm render` / `lirm demo` (nothing to download) and as the seed of the synthetic
training-data generator. Every object is a list of MeshData parts in the world frame of DESIGN.md
§3 (+Z up, front toward -Y, centred at the origin, bounding radius TARGET_RADIUS) whose albedo,
roughness and metallic maps each carry their own pattern, so that a material decoder has to tell
them apart. `seed` varies colours, patterns and proportions a little, deterministically.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lirm.renderer.material import PBRMaterial
from lirm.renderer.mesh import MeshData

from .mesh_builders import (
    BOX_FACES,
    Geometry,
    LatheLayout,
    LatheRows,
    Profile,
    catmull_rom,
    lathe,
    resample_polyline,
    rounded_box,
    sweep_tube,
)
from .texture_patterns import (
    MaterialCanvas,
    box,
    jitter_color,
    rounded_rect,
    sample_image,
    smoothstep,
    square_wave,
    srgb,
    star,
    streaks,
    text_mask,
    triangle_wave,
    value_noise,
)

BUILTIN_OBJECTS = ("vase", "mug", "toy_block", "bottle")
TARGET_RADIUS = 0.92  # bounding radius after fitting: inside the unit sphere with a margin for normal maps

GOLD = srgb((0.98, 0.84, 0.52))
BISQUE = srgb((0.80, 0.68, 0.55))
METALS = {
    "silver": srgb((0.90, 0.90, 0.91)),
    "gunmetal": srgb((0.56, 0.57, 0.60)),
    "brass": srgb((0.92, 0.80, 0.52)),
    "copper": srgb((0.95, 0.66, 0.55)),
}


@dataclass
class _Part:
    name: str
    geometry: Geometry
    material: PBRMaterial


def make_builtin_object(name: str, seed: int = 0) -> list[MeshData]:
    """The built-in object `name` (one of BUILTIN_OBJECTS) as MeshData parts; `seed` picks a variant."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown built-in object {name!r}; choose one of: {', '.join(BUILTIN_OBJECTS)}")
    # Salting with the object's name keeps e.g. vase seed 3 unrelated to mug seed 3.
    salt = int.from_bytes(name.encode(), "little") % (2**63)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed) % (2**63), salt]))
    return _fit(name, _BUILDERS[name](rng))


def _fit(object_name: str, parts: list[_Part]) -> list[MeshData]:
    """Centre the bounding box at the origin and scale to TARGET_RADIUS (normals and UVs are unaffected)."""
    allp = np.vstack([p.geometry.positions for p in parts])
    centre = 0.5 * (allp.min(0) + allp.max(0))
    scale = TARGET_RADIUS / np.linalg.norm(allp - centre, axis=1).max()
    return [
        MeshData(
            positions=(p.geometry.positions - centre) * scale,
            indices=p.geometry.indices,
            normals=p.geometry.normals,
            uvs=p.geometry.uvs,
            material=p.material,
            name=f"{object_name}/{p.name}",
        )
        for p in parts
    ]


# ---------------------------------------------------------------------------------------------
# Helpers for painting lathes: rows of the texture know where on the profile they lie.


def _lathe_grid(layout: LatheLayout, size: int) -> tuple[LatheRows, np.ndarray]:
    return layout.rows(size), ((np.arange(size) + 0.5) / size)[None, :]


def _lathe_texel_sizes(layout: LatheLayout, rows: LatheRows, size: int) -> tuple[np.ndarray, np.ndarray]:
    """World size of a texel across (around the axis) and down (along the profile), per row."""
    half = 0.5 / size
    ds = np.interp(rows.v + half, layout.v, layout.s) - np.interp(rows.v - half, layout.v, layout.s)
    return (2 * np.pi * np.maximum(rows.r, 1e-3) / size)[:, None], np.maximum(ds, 1e-6)[:, None]


def _patch_on_lathe(
    rows: LatheRows,
    u: np.ndarray,
    patch_hw: tuple[int, int],
    centre_u: float,
    s_top: float,
    width: float,
    height: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates into a flat (h, w) patch laid on a lathe like a decal: centred at `centre_u`,
    its top edge at profile arc length `s_top`, running up the profile as the image runs up."""
    ph, pw = patch_hw
    x = (u - centre_u) * 2 * np.pi * rows.r[:, None]
    y = (s_top - rows.s)[:, None]
    map_x = (x / width + 0.5) * pw - 0.5
    map_y = np.broadcast_to(y / height * ph - 0.5, map_x.shape)
    return map_x, map_y


def _s_at_height(layout: LatheLayout, section: str, z: float) -> float:
    """Arc length where a section that rises monotonically reaches height z."""
    i = layout.section_names.index(section)
    lo = layout.section_start_v[i]
    hi = layout.section_start_v[i + 1] if i + 1 < len(layout.section_start_v) else 1.0
    sel = (layout.v >= lo) & (layout.v <= hi)
    return float(np.interp(z, layout.z[sel], layout.s[sel]))


def _glaze_speckles(rng: np.random.Generator, size: int) -> np.ndarray:
    """Iron specks of speckled stoneware: sparse dark dots."""
    n = value_noise(rng, size, size, cells=(size // 4, size // 4), octaves=1)
    return smoothstep(0.86, 0.93, n)


# ---------------------------------------------------------------------------------------------
# Vase: thrown stoneware with painted bands, a glaze that changes gloss by band and gold lustre.


def _vase(rng: np.random.Generator) -> list[_Part]:
    H = 2.0
    foot = 0.30 * rng.uniform(0.92, 1.08)
    belly = 0.60 * rng.uniform(0.92, 1.06)
    belly_z = rng.uniform(0.88, 1.02)
    neck = 0.24 * rng.uniform(0.9, 1.1)
    lip = neck * rng.uniform(1.25, 1.45)
    wall, chamfer, zb = 0.04, 0.02, 0.12

    knots = np.array(
        [
            (foot, chamfer),
            (foot * 1.18, 0.18),
            (belly * 0.93, belly_z - 0.35),
            (belly, belly_z),
            (belly * 0.88, belly_z + 0.30),
            (neck * 1.35, 1.52),
            (neck, 1.72),
            (neck * 1.1, 1.88),
            (lip, H),
        ]
    )
    outer = catmull_rom(knots, 8)
    inner = outer[outer[:, 1] >= zb + 0.14][::-1] - np.array([wall, 0.0])

    p = Profile(0.0, 0.0, "bottom")
    p.line_to(foot - chamfer, 0.0, steps=4, density=0.5).corner()
    p.line_to(foot, chamfer).corner()
    p.section("outer").polyline(outer[1:]).corner()
    p.section("rim").line_to(lip - wall, H, steps=2).corner()
    p.section("inner").polyline(inner[1:], density=0.35)
    ri = inner[-1, 0]
    p.quad_to((ri, zb), (ri - 0.12, zb), steps=6, density=0.35)
    p.section("inner_bottom").line_to(0.0, zb, steps=4, density=0.35)
    geometry, layout = lathe(p, segments=128)

    S = 1024
    rows, u = _lathe_grid(layout, S)
    t = (rows.z / H)[:, None]
    outer_m = rows.on(layout, "outer")[:, None].astype(np.float32)
    inner_m = rows.on(layout, "inner", "inner_bottom")[:, None].astype(np.float32)
    glaze = jitter_color(["#1f3f8c", "#0e5f66", "#7a1f1f", "#2d2a5a"][rng.integers(4)], rng)
    cream = jitter_color("#eee5cf", rng, hue=0.01, sat=0.04, val=0.03)
    accent = jitter_color(["#c8623a", "#d9a441", "#3f7f5f"][rng.integers(3)], rng)
    neck_glaze = jitter_color(["#8fb39a", "#b7c4c9", "#c9b48f"][rng.integers(3)], rng)

    cv = MaterialCanvas(S, S, glaze, 0.12)
    pool = value_noise(rng, S, S, cells=(8, 8), octaves=4)
    cv.albedo *= (0.88 + 0.24 * pool)[..., None]  # glaze pools thicker and darker in places
    cv.roughness += 0.06 * (pool - 0.5)
    cv.paint(inner_m, glaze * 0.7, roughness=0.1)

    j = rng.uniform(-0.01, 0.01, 8)
    bands = {
        "stripes": (0.11 + j[0], 0.30 + j[1]),
        "zigzag": (0.34 + j[1], 0.43 + j[2]),
        "dots": (0.47 + j[2], 0.69 + j[3]),
        "neck": (0.73 + j[3], 0.93),
    }
    soft = 0.0015
    # Cream vertical stripes, matte, over the glossy glaze.
    lo, hi = bands["stripes"]
    k = int(rng.integers(9, 15)) * 2
    stripes = square_wave(u * k, duty=rng.uniform(0.35, 0.55), soft=0.03)
    cv.paint(outer_m * box(t, lo, hi, soft) * stripes, cream, roughness=0.48)
    # Zigzag: a cream ground with an accent line, semi-gloss.
    lo, hi = bands["zigzag"]
    zband = outer_m * box(t, lo, hi, soft)
    cv.paint(zband, cream, roughness=0.32)
    y = (t - lo) / (hi - lo)
    zig = 0.2 + 0.6 * triangle_wave(u * int(rng.integers(10, 18)))
    cv.paint(zband * box(y - zig, -0.12, 0.12, 0.03), GOLD, roughness=0.26, metallic=1.0)  # lustre line
    # Raised slip dots in staggered rows on the belly, matte.
    lo, hi = bands["dots"]
    n_around = int(rng.integers(16, 22))
    dots = np.zeros((S, S), dtype=np.float32)
    band_rows = np.flatnonzero(rows.on(layout, "outer") & (t[:, 0] > lo - 0.02) & (t[:, 0] < hi + 0.02))
    tb, rb = t[band_rows], rows.r[band_rows, None]
    for q in range(3):
        tq = lo + (q + 0.5) * (hi - lo) / 3
        dx = (np.mod(u * n_around - 0.5 * (q % 2), 1.0) - 0.5) / n_around * 2 * np.pi * rb
        dots[band_rows] += 1.0 - smoothstep(0.040, 0.048, np.hypot(dx, (tb - tq) * H))
    cv.paint(dots, cream, roughness=0.58, height=0.004)
    # Neck: a second glaze whose gloss breaks up (crawling), independent of any colour edge.
    lo, hi = bands["neck"]
    nmask = outer_m * box(t, lo, hi, soft)
    crawl = value_noise(rng, S, S, cells=(16, 32), octaves=3)
    cv.paint(nmask, neck_glaze * (0.9 + 0.2 * crawl)[..., None], roughness=0.12 + 0.5 * smoothstep(0.4, 0.7, crawl))
    # Incised lines at band edges, filled with the accent colour.
    for edge in (bands["stripes"][0], bands["stripes"][1] + 0.02, bands["zigzag"][1] + 0.02, bands["neck"][0] - 0.015):
        line = outer_m * np.exp(-(((t - edge) * H / 0.006) ** 2))
        cv.paint(line, accent, roughness=0.4, height=-0.003)
    # Unglazed foot and base, then gold lustre on a foot ring and around the rim (both sides).
    bis_noise = value_noise(rng, S, S, cells=(64, 64), octaves=2)
    bisque = BISQUE * (0.92 + 0.16 * bis_noise)[..., None]
    foot_m = np.maximum(rows.on(layout, "bottom")[:, None], outer_m * box(t, -1.0, 0.045, soft))
    cv.paint(foot_m, bisque, roughness=0.85 + 0.1 * (bis_noise - 0.5), metallic=0.0)
    gold_rough = 0.2 + 0.12 * streaks(rng, S, S)
    cv.paint(outer_m * box(t, 0.06 + j[4], 0.08 + j[4], soft), GOLD, roughness=gold_rough, metallic=1.0)
    rim = np.maximum(rows.on(layout, "rim")[:, None], outer_m * box(t, 0.955 + j[5], 2.0, soft))
    rim = np.maximum(rim, rows.on(layout, "inner")[:, None] * box(t, 0.93, 2.0, soft))
    cv.paint(rim, GOLD, roughness=gold_rough, metallic=1.0)

    tw, th = _lathe_texel_sizes(layout, rows, S)
    return [_Part("body", geometry, cv.material("vase_glaze", tw, th))]


# ---------------------------------------------------------------------------------------------
# Mug: glossy glazed stoneware, a matte printed label with text, a checker strip and a foil logo.


def _mug(rng: np.random.Generator) -> list[_Part]:
    Hm = 0.95 * rng.uniform(0.94, 1.06)
    Rb = 0.40 * rng.uniform(0.95, 1.05)
    Rt = Rb * rng.uniform(1.0, 1.08)
    wall, zb = 0.035, 0.07
    bulge = 0.015
    z1 = zb + 0.06

    p = Profile(0.0, 0.012, "foot")
    p.line_to(Rb - 0.07, 0.012, steps=3, density=0.5).corner()
    p.line_to(Rb - 0.06, 0.0, density=0.5).corner()
    p.line_to(Rb - 0.03, 0.0, density=0.5)
    p.arc((Rb - 0.03, 0.03), 90.0, 6, density=0.5)
    cx = 0.5 * (Rb + Rt) + bulge
    p.section("outer").quad_to((cx, Hm / 2), (Rt, Hm), steps=28)
    p.section("lip").arc((Rt - wall / 2, Hm), 180.0, 10)
    p.section("inner").quad_to((cx - wall, Hm / 2), (Rb - wall, z1), steps=24, density=0.4)
    p.arc((Rb - wall - 0.06, z1), -90.0, 6, density=0.4)
    p.section("inner_bottom").line_to(0.0, zb, steps=3, density=0.4)
    body_geo, layout = lathe(p, segments=128)

    def r_out(z: float) -> float:
        # The outer wall is a quadratic Bezier in (r, z); invert z for its parameter.
        a, b, c = 0.03 - 2 * (Hm / 2) + Hm, 2 * (Hm / 2 - 0.03), 0.03 - z
        s = -c / b if abs(a) < 1e-12 else (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
        return (1 - s) ** 2 * Rb + 2 * (1 - s) * s * cx + s**2 * Rt

    # Handle: an elliptical-section tube on a half-ellipse, its ends buried in the wall.
    z_top, z_bot = Hm * rng.uniform(0.76, 0.82), Hm * rng.uniform(0.22, 0.28)
    zc, b = 0.5 * (z_top + z_bot), 0.5 * (z_top - z_bot)
    reach = 0.25 * rng.uniform(0.9, 1.1)
    xc = r_out(zc) + 0.02
    phi = np.linspace(np.pi / 2, -np.pi / 2, 80)
    arc = np.stack([xc + reach * np.cos(phi), np.zeros_like(phi), zc + b * np.sin(phi)], 1)
    top_stub = np.stack([np.linspace(r_out(z_top) - wall / 2, xc, 6), np.zeros(6), np.full(6, z_top)], 1)
    bot_stub = np.stack([np.linspace(xc, r_out(z_bot) - wall / 2, 6), np.zeros(6), np.full(6, z_bot)], 1)
    path = resample_polyline(np.vstack([top_stub, arc, bot_stub]), 72)
    handle_geo = sweep_tube(path, side=(0.0, 1.0, 0.0), radii=(0.036, 0.058), segments=32)

    S = 1024
    rows, u = _lathe_grid(layout, S)
    glaze = jitter_color(["#c8372d", "#1f6f78", "#e0a526", "#263b6e", "#4f7f45"][rng.integers(5)], rng)
    white = jitter_color("#efece4", rng, hue=0.01, sat=0.03, val=0.02)
    outer_m = rows.on(layout, "outer", "lip")[:, None].astype(np.float32)

    cv = MaterialCanvas(S, S, glaze, 0.07)
    n1 = value_noise(rng, S, S, cells=(8, 8), octaves=4)
    cv.albedo *= (0.92 + 0.16 * n1)[..., None]
    cv.roughness += 0.04 * (n1 - 0.5)
    cv.paint(rows.on(layout, "inner", "inner_bottom")[:, None], white, roughness=0.09)
    cv.albedo *= (1.0 - 0.45 * _glaze_speckles(rng, S))[..., None]
    cv.paint(rows.on(layout, "foot")[:, None], BISQUE, roughness=0.82, metallic=0.0)
    # Lustre line around the lip.
    s_outer_top = float(np.interp(layout.section_start_v[layout.section_names.index("lip")], layout.v, layout.s))
    s_inner_top = float(np.interp(layout.section_start_v[layout.section_names.index("inner")], layout.v, layout.s))
    rim = (rows.s > s_outer_top - 0.02) & (rows.s < s_inner_top + 0.012)
    metal = GOLD if rng.random() < 0.5 else METALS["silver"]
    cv.paint(rim[:, None], metal, roughness=0.18, metallic=1.0)

    # Label decal, drawn flat at world scale then wrapped onto the front (u = 0.5).
    lw, lh = 0.78 * rng.uniform(0.92, 1.05), Hm * 0.5
    s_top = float(np.interp(layout.section_start_v[1], layout.v, layout.s)) + (Hm - 0.03) * 0.78
    ppu = 700.0
    ph, pw = int(lh * ppu), int(lw * ppu)
    yy, xx = np.mgrid[0:ph, 0:pw].astype(np.float32)
    X, Y = (xx + 0.5) / ppu - lw / 2, lh / 2 - (yy + 0.5) / ppu  # metres-like units, Y up
    label = rounded_rect(X, Y, lw / 2, lh / 2, 0.05, 1.0 / ppu)
    frame = label - rounded_rect(X, Y, lw / 2 - 0.018, lh / 2 - 0.018, 0.035, 1.0 / ppu)
    frame = np.clip(frame - (label - rounded_rect(X, Y, lw / 2 - 0.012, lh / 2 - 0.012, 0.04, 1.0 / ppu)), 0, 1)
    word = ["LIRM", "CAFE", "BREW", "HELLO", "MOKA", "TEA"][rng.integers(6)]
    txt = np.zeros((ph, pw), np.float32)
    ty0, ty1 = int(0.36 * ph), int(0.70 * ph)
    tx0, tx1 = int(0.08 * pw), int(0.92 * pw)
    txt[ty0:ty1, tx0:tx1] = text_mask(word, tx1 - tx0, ty1 - ty0, weight=0.12)
    cy0, cy1 = 0.76 * ph, 0.88 * ph
    n_sq = int(rng.integers(8, 13))
    in_strip = box(yy, cy0, cy1, 0.5) * box(xx, 0.1 * pw, 0.9 * pw, 0.5)
    sq = (np.floor((xx - 0.1 * pw) / (0.8 * pw) * n_sq) + np.floor((yy - cy0) / (cy1 - cy0) * 2)) % 2
    checker_dark = in_strip * sq
    checker_light = in_strip * (1 - sq)
    logo_r = 0.085
    LX, LY = X, Y - (lh / 2 - 0.17 * lh - 0.02)
    ring = box(np.hypot(LX, LY), logo_r - 0.012, logo_r, 1.0 / ppu)
    logo = np.maximum(ring, star(LX, LY, logo_r * 0.72, points=5, inner=0.45, soft=1.0 / ppu))

    mx, my = _patch_on_lathe(rows, u, (ph, pw), 0.5, s_top, lw, lh)
    on = lambda img: sample_image(img, mx, my) * outer_m  # noqa: E731
    paper = jitter_color(["#f3ecd9", "#fdfbf5", "#f2d9c4"][rng.integers(3)], rng, hue=0.01, sat=0.03, val=0.02)
    ink = jitter_color(["#1d1d24", "#3a2418", "#17324d"][rng.integers(3)], rng, hue=0.01, sat=0.05, val=0.04)
    cv.paint(on(label), paper, roughness=0.55, metallic=0.0)
    cv.paint(on(frame), ink, roughness=0.42)
    cv.paint(on(checker_dark), ink, roughness=0.35)
    cv.paint(on(checker_light), glaze, roughness=0.65)
    cv.paint(on(txt), ink, roughness=0.42)
    cv.paint(on(logo), metal, roughness=0.25, metallic=1.0)
    body_mat = cv.material("mug_glaze")

    hs = 512
    hc = MaterialCanvas(hs, hs, glaze, 0.07)
    hn = value_noise(rng, hs, hs, cells=(4, 8), octaves=4)
    hc.albedo *= (0.9 + 0.2 * hn)[..., None]
    hc.roughness += 0.04 * (hn - 0.5)
    hc.albedo *= (1.0 - 0.45 * _glaze_speckles(rng, hs))[..., None]
    return [_Part("body", body_geo, body_mat), _Part("handle", handle_geo, hc.material("mug_handle_glaze"))]


# ---------------------------------------------------------------------------------------------
# Toy block: wooden block, painted checker faces with per-square gloss, bare wood on the rounded
# edges, a metal stripe and an embossed letter.


def _toy_block(rng: np.random.Generator) -> list[_Part]:
    half = 0.5 * rng.uniform(0.94, 1.06, 3)
    radius = 0.07 * rng.uniform(0.85, 1.15)
    S, pad = 1024, 8
    C = S // 3
    cells = {}
    for k, (name, *_rest) in enumerate(BOX_FACES):
        col, row = k % 3, k // 3
        cells[name] = ((col * C + pad) / S, (row * C + pad) / S, ((col + 1) * C - pad) / S, ((row + 1) * C - pad) / S)
    geometry, axes = rounded_box(tuple(half), radius, cells)

    colors = ["#d63a32", "#2f62c8", "#3f9a4a", "#f0c330", "#ee7d25", "#8a4fb0"]
    order = rng.permutation(len(colors))
    letters = rng.choice(list("ABCDEFGHJKLMNPRSTUWXYZ"), size=4, replace=False)  # one per side
    digit = str(int(rng.integers(1, 10)))
    metal = METALS[["silver", "brass", "copper"][rng.integers(3)]]
    wood = jitter_color("#d9b382", rng, hue=0.01, sat=0.05, val=0.04)
    n_sq = int(rng.integers(3, 6))

    atlas = MaterialCanvas(S, S, wood, 0.7)
    inner = C - 2 * pad
    a = ((np.arange(C) + 0.5 - pad) / inner * 2 - 1)[None, :].astype(np.float32)
    b = (1 - (np.arange(C) + 0.5 - pad) / inner * 2)[:, None].astype(np.float32)
    for k, (name, *_rest) in enumerate(BOX_FACES):
        r_ax, up_ax = axes[name]
        texel = float(np.mean([2 * half[r_ax], 2 * half[up_ax]]) / inner)
        base = jitter_color(colors[order[k]], rng, hue=0.01, sat=0.05, val=0.04)
        tint = np.clip(base + 0.45 * (1 - base), 0, 1)
        cell = MaterialCanvas(C, C, base, 0.5)
        ia = np.clip(np.floor((a + 1) / 2 * n_sq), 0, n_sq - 1).astype(int)
        ib = np.clip(np.floor((b + 1) / 2 * n_sq), 0, n_sq - 1).astype(int)
        square_rough = rng.uniform(0.12, 0.75, (n_sq, n_sq)).astype(np.float32)
        odd = ((ia + ib) % 2).astype(np.float32)
        cell.paint(odd, tint)
        cell.roughness[:] = square_rough[ib, ia]
        # Bare wood where the edges are rounded off; grain runs along the face's rows.
        grain = value_noise(rng, C, C, cells=(64, 2), octaves=3)
        edge = 1 - (1 - smoothstep(0.82, 0.86, np.abs(a))) * (1 - smoothstep(0.82, 0.86, np.abs(b)))
        cell.paint(edge, wood * (0.85 + 0.3 * grain)[..., None], roughness=0.6 + 0.25 * grain, metallic=0.0)
        # Metal: a band round the sides, a diagonal across a top corner.
        if name in ("front", "right", "back", "left"):
            band = box(b, -0.76, -0.58, 0.01) * (1 - edge)
            glyph_box = (-0.48, 0.62)
        elif name == "top":
            band = box(a + b, 0.95, 1.25, 0.01) * (1 - edge)
            glyph_box = (-0.55, 0.55)
        else:
            band = np.zeros((C, C), np.float32)
            glyph_box = (-0.55, 0.55)
        brushed = streaks(rng, C, C)
        cell.paint(band, metal * (0.94 + 0.08 * brushed)[..., None], roughness=0.2 + 0.12 * brushed, metallic=1.0)
        # Embossed glyph: raised, painted, satin.
        y0 = int(round((1 - glyph_box[1]) / 2 * inner + pad))
        y1 = int(round((1 - glyph_box[0]) / 2 * inner + pad))
        x0, x1 = int(round(0.22 * inner + pad)), int(round(0.78 * inner + pad))
        glyph = np.zeros((C, C), np.float32)
        if name == "top":
            glyph = star(a, b, 0.5, points=5, inner=0.45, soft=0.01)
        else:
            char = digit if name == "bottom" else letters[k]
            glyph[y0:y1, x0:x1] = text_mask(char, x1 - x0, y1 - y0, font=cv2.FONT_HERSHEY_TRIPLEX, weight=0.16)
        relief = cv2.GaussianBlur(glyph, (0, 0), 1.5)
        ink = srgb("#f7f3e8") if base.mean() < 0.55 else srgb("#23202a")
        cell.paint(glyph, ink, roughness=0.3, metallic=0.0)
        cell.paint(np.ones((C, C), np.float32), height=0.012 * relief)
        col, row = k % 3, k // 3
        atlas.blit(cell, row * C, col * C, height_scale=1.0 / texel)  # height in texels: one map, one scale
    return [_Part("block", geometry, atlas.material("toy_block_paint"))]


# ---------------------------------------------------------------------------------------------
# Bottle: powder-coated metal bottle with a glossy printed label, foil emblem, exposed brushed
# base, and a brushed, knurled metal cap with a rubber seal.


def _bottle(rng: np.random.Generator) -> list[_Part]:
    R = 0.36 * rng.uniform(0.92, 1.08)
    Rn = 0.12 * rng.uniform(0.92, 1.08)
    sz = 1.05 * rng.uniform(0.94, 1.04)
    nz = sz + 0.33
    f = 0.05
    Rc = Rn + 0.035
    cz0 = nz + 0.065
    top = cz0 + 0.1
    cz1 = cz0 + 0.2 * rng.uniform(0.9, 1.15)

    knots = np.array(
        [(R, f), (R, 0.5 * sz), (R, sz), (R * 0.96, sz + 0.12), (R * 0.72, sz + 0.24), (Rn * 1.3, nz - 0.07), (Rn, nz)]
    )
    p = Profile(0.0, 0.0, "bottom")
    p.line_to(R - f, 0.0, steps=4, density=0.5)
    p.arc((R - f, f), 90.0, 6, density=0.5)
    p.section("wall").polyline(catmull_rom(knots, 8)[1:])
    p.line_to(Rn, nz + 0.02).corner()
    p.section("collar").arc((Rn, nz + 0.035), 180.0, 8).corner()
    p.section("neck").line_to(Rn, top, steps=2).corner()
    p.section("top").line_to(0.0, top, steps=2, density=0.3)
    body_geo, layout = lathe(p, segments=128)

    q = Profile(0.0, cz0, "bottom")
    q.line_to(Rc - 0.012, cz0, steps=2, density=0.6).corner()
    q.line_to(Rc, cz0 + 0.012).corner()
    q.section("side").line_to(Rc, cz1 - 0.025, steps=8)
    q.arc((Rc - 0.025, cz1 - 0.025), 90.0, 6)
    q.section("top").line_to(0.0, cz1, steps=6)
    cap_geo, cap_layout = lathe(q, segments=128)

    S = 1024
    rows, u = _lathe_grid(layout, S)
    t = (rows.z / nz)[:, None]
    paint_color = jitter_color(["#2a5f9e", "#d0574a", "#2f7d5b", "#26262b", "#e2b93b"][rng.integers(5)], rng)
    dark = paint_color * 0.55
    light = np.clip(paint_color + 0.25 * (1 - paint_color), 0, 1)
    ombre = dark + (light - dark) * smoothstep(0.05, 0.95, t)[..., None]
    coat = value_noise(rng, S, S, cells=(32, 32), octaves=3)
    cv = MaterialCanvas(S, S, paint_color, 0.5)
    cv.paint(np.ones((S, S), np.float32), ombre * (0.96 + 0.08 * coat)[..., None], roughness=0.5 + 0.1 * (coat - 0.5))
    wall_m = rows.on(layout, "wall")[:, None].astype(np.float32)
    metal = METALS[["silver", "gunmetal", "brass", "copper"][rng.integers(4)]]
    brushed = streaks(rng, S, S)
    metal_tex = metal * (0.93 + 0.1 * brushed)[..., None]
    metal_rough = 0.3 + 0.1 * brushed
    base_m = np.maximum(rows.on(layout, "bottom")[:, None], wall_m * box(t, -1.0, 0.07, 0.001))
    cv.paint(base_m, metal_tex, roughness=metal_rough, metallic=1.0)
    cv.paint(rows.on(layout, "collar")[:, None], metal_tex, roughness=metal_rough, metallic=1.0)

    L0, L1 = 0.30 + rng.uniform(-0.03, 0.03), 0.62 + rng.uniform(-0.03, 0.03)
    band = wall_m * box(t, L0, L1, 0.001)
    paper = jitter_color("#f4f1ea", rng, hue=0.01, sat=0.03, val=0.02)
    cv.paint(band, paper, roughness=0.2, metallic=0.0)
    for edge in (L0 - 0.014, L1 + 0.014):
        cv.paint(wall_m * box(t, edge - 0.004, edge + 0.004, 0.001), metal_tex, roughness=0.28, metallic=1.0)
    # Diagonal stripes round the back of the label, the front is left for the print.
    diag = square_wave((u * 2 * np.pi * rows.r[:, None] + rows.z[:, None]) / 0.09, duty=0.4, soft=0.05)
    back = 1 - box(u, 0.28, 0.72, 0.01)
    cv.paint(band * back * diag, paint_color, roughness=0.32)

    lw = 0.5
    lh = (L1 - L0) * nz * 0.9
    s_top = _s_at_height(layout, "wall", L1 * nz) - (L1 - L0) * nz * 0.05
    ppu = 700.0
    ph, pw = int(lh * ppu), int(lw * ppu)
    yy, xx = np.mgrid[0:ph, 0:pw].astype(np.float32)
    X, Y = (xx + 0.5) / ppu - lw / 2, lh / 2 - (yy + 0.5) / ppu
    word = ["AQUA", "NORD", "PEAK", "FJORD", "TIDE"][rng.integers(5)]
    txt = np.zeros((ph, pw), np.float32)
    ty0, ty1 = int(0.58 * ph), int(0.88 * ph)
    txt[ty0:ty1] = text_mask(word, pw, ty1 - ty0, font=cv2.FONT_HERSHEY_SIMPLEX, weight=0.14)
    # Foil emblem: two mountain peaks as an outline.
    ey = Y - (lh / 2 - 0.3 * lh)
    peak1 = ey + 0.9 * np.abs(X + 0.04) - 0.08
    peak2 = ey + 1.1 * np.abs(X - 0.07) - 0.05
    ridge = np.minimum(np.abs(peak1), np.abs(peak2))
    under = (peak1 < 0) & (peak2 < 0)
    emblem = (1 - smoothstep(0.006, 0.012, ridge)) * (ey > -0.09) * ~under * (np.abs(X) < 0.2)
    emblem = np.maximum(emblem, box(ey, -0.1, -0.09, 1.0 / ppu) * box(X, -0.2, 0.2, 1.0 / ppu))
    mx, my = _patch_on_lathe(rows, u, (ph, pw), 0.5, s_top, lw, lh)
    ink = paint_color * 0.6
    cv.paint(sample_image(txt, mx, my) * band, ink, roughness=0.42)
    cv.paint(sample_image(emblem.astype(np.float32), mx, my) * band, metal, roughness=0.22, metallic=1.0)
    body_mat = cv.material("bottle_paint")

    CS = 512
    crows, cu = _lathe_grid(cap_layout, CS)
    cap_metal = METALS[["silver", "gunmetal", "silver", "brass"][rng.integers(4)]]
    cb = streaks(rng, CS, CS)  # brushed round the axis: streaks run along u
    cc = MaterialCanvas(CS, CS, cap_metal, 0.35, metallic=1.0)
    cc.paint(np.ones((CS, CS), np.float32), cap_metal * (0.92 + 0.12 * cb)[..., None], roughness=0.3 + 0.12 * cb)
    side = crows.on(cap_layout, "side")[:, None].astype(np.float32)
    k = int(rng.integers(40, 56))
    knurl_rows = side * box(crows.z[:, None], cz0 + 0.04, cz1 - 0.035, 0.002)
    cc.paint(knurl_rows, roughness=0.42, height=0.004 * triangle_wave(cu * k))
    seal = np.maximum(crows.on(cap_layout, "bottom")[:, None], side * box(crows.z[:, None], 0.0, cz0 + 0.022, 0.001))
    cc.paint(seal, srgb("#141414"), roughness=0.9, metallic=0.0)
    ctw, cth = _lathe_texel_sizes(cap_layout, crows, CS)
    return [
        _Part("body", body_geo, body_mat),
        _Part("cap", cap_geo, cc.material("bottle_cap_brushed_metal", ctw, cth)),
    ]


_BUILDERS = {"vase": _vase, "mug": _mug, "toy_block": _toy_block, "bottle": _bottle}
assert tuple(_BUILDERS) == BUILTIN_OBJECTS
