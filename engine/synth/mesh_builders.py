"""Geometry for procedural objects: surfaces of revolution (lathes), swept tubes and rounded boxes.

Conventions (DESIGN.md §3, renderer.mesh): right-handed, +Z up, triangles counter-clockwise seen
from outside, UVs in glTF's convention (u right, v down from the top of the texture image).
Builders return float64 arrays in their own units; callers scale the finished object.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_EPS = 1e-9


@dataclass
class Geometry:
    positions: np.ndarray  # (V, 3)
    normals: np.ndarray  # (V, 3) unit
    uvs: np.ndarray  # (V, 2)
    indices: np.ndarray  # (F, 3) int64


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-20)


def catmull_rom(points: np.ndarray, steps_per_span: int) -> np.ndarray:
    """Uniform Catmull-Rom curve through `points` (K, D), ends included."""
    p = np.asarray(points, dtype=np.float64)
    ext = np.vstack([2 * p[0] - p[1], p, 2 * p[-1] - p[-2]])
    t = (np.arange(steps_per_span, dtype=np.float64) / steps_per_span)[:, None]
    out = []
    for i in range(len(p) - 1):
        p0, p1, p2, p3 = ext[i : i + 4]
        out.append(
            0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t**2 + (3 * p1 - p0 - 3 * p2 + p3) * t**3)
        )
    out.append(p[-1:])
    return np.vstack(out)


class Profile:
    """A lathe profile in the (r, z) half-plane.

    Walk it with the solid on the left: the outward normal of a step (dr, dz) is (dz, -dr). A closed
    solid starts and ends on the axis (r = 0). Points marked with `corner()` become hard creases
    (split normals); `density` weights a step's share of the texture's v range, so hidden inner
    surfaces can take fewer texels; `section()` names the stretch that starts at the current point
    so that painters can tell the outside from the rim or the inside.
    """

    def __init__(self, r: float, z: float, section: str = "start"):
        self._points: list[tuple[float, float]] = [(float(r), float(z))]
        self._creases: list[bool] = [False]
        self._density: list[float] = []
        self._sections: list[tuple[str, int]] = [(section, 0)]

    @property
    def last(self) -> np.ndarray:
        return np.array(self._points[-1])

    def _extend(self, pts: np.ndarray, density: float) -> Profile:
        for p in np.asarray(pts, dtype=np.float64).reshape(-1, 2):
            if np.hypot(*(p - self.last)) < 1e-9:
                continue
            self._points.append((float(p[0]), float(p[1])))
            self._creases.append(False)
            self._density.append(float(density))
        return self

    def line_to(self, r: float, z: float, steps: int = 1, density: float = 1.0) -> Profile:
        t = np.linspace(0.0, 1.0, steps + 1)[1:, None]
        return self._extend(self.last + (np.array([r, z]) - self.last) * t, density)

    def arc(self, center: tuple[float, float], sweep_deg: float, steps: int, density: float = 1.0) -> Profile:
        """Turn the current point about `center` by `sweep_deg` (positive = counter-clockwise in (r, z))."""
        c = np.asarray(center, dtype=np.float64)
        d = self.last - c
        a0, rad = np.arctan2(d[1], d[0]), np.hypot(*d)
        a = a0 + np.radians(sweep_deg) * np.linspace(0.0, 1.0, steps + 1)[1:]
        return self._extend(c + rad * np.stack([np.cos(a), np.sin(a)], 1), density)

    def quad_to(
        self, control: tuple[float, float], end: tuple[float, float], steps: int, density: float = 1.0
    ) -> Profile:
        t = np.linspace(0.0, 1.0, steps + 1)[1:, None]
        p0, p1, p2 = self.last, np.asarray(control, float), np.asarray(end, float)
        return self._extend((1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t**2 * p2, density)

    def polyline(self, points: np.ndarray, density: float = 1.0) -> Profile:
        return self._extend(points, density)

    def corner(self) -> Profile:
        self._creases[-1] = True
        return self

    def section(self, name: str) -> Profile:
        start = len(self._points) - 1
        if self._sections[-1][1] == start:
            self._sections[-1] = (name, start)
        else:
            self._sections.append((name, start))
        return self

    @property
    def points(self) -> np.ndarray:
        return np.array(self._points)

    @property
    def creases(self) -> np.ndarray:
        return np.array(self._creases)

    @property
    def density(self) -> np.ndarray:
        return np.array(self._density)

    @property
    def sections(self) -> list[tuple[str, int]]:
        return list(self._sections)


@dataclass
class LatheRows:
    """What each texture row of a lathe's texture lies on (row centres, top row first)."""

    v: np.ndarray  # (H,)
    r: np.ndarray  # radius at the row
    z: np.ndarray  # height at the row
    s: np.ndarray  # arc length along the profile from its start
    section: np.ndarray  # (H,) index into LatheLayout.section_names

    def on(self, layout: LatheLayout, *names: str) -> np.ndarray:
        ids = [layout.section_names.index(n) for n in names]
        return np.isin(self.section, ids)


@dataclass
class LatheLayout:
    """How a lathe's texture maps onto it: u = angle (u = 0.5 faces -Y), v = along the profile."""

    r: np.ndarray
    z: np.ndarray
    s: np.ndarray
    v: np.ndarray
    section_names: tuple[str, ...]
    section_start_v: np.ndarray
    theta0: float

    def rows(self, height: int) -> LatheRows:
        vc = (np.arange(height) + 0.5) / height
        sec = np.searchsorted(self.section_start_v, vc, side="right") - 1
        return LatheRows(
            v=vc,
            r=np.interp(vc, self.v, self.r),
            z=np.interp(vc, self.v, self.z),
            s=np.interp(vc, self.v, self.s),
            section=np.clip(sec, 0, len(self.section_names) - 1),
        )

    def z_of_section(self, name: str) -> tuple[float, float]:
        """Height range of a section (for painting bands in object height)."""
        i = self.section_names.index(name)
        lo = self.section_start_v[i]
        hi = self.section_start_v[i + 1] if i + 1 < len(self.section_start_v) else 1.0
        sel = (self.v >= lo - 1e-12) & (self.v <= hi + 1e-12)
        return float(self.z[sel].min()), float(self.z[sel].max())


def lathe(profile: Profile, segments: int = 128, theta0: float = np.pi / 2) -> tuple[Geometry, LatheLayout]:
    """Revolve `profile` about +Z. theta = theta0 + 2*pi*u; the default puts the u seam at the back (+Y)
    and u = 0.5 at the front (-Y), with u growing to the right as seen from the front."""
    pts = profile.points
    creases = profile.creases
    n = len(pts)
    if n < 2:
        raise ValueError("a lathe profile needs at least two points")
    r = pts[:, 0].copy()
    z = pts[:, 1]
    if (r < -_EPS).any() or (r[1:-1] < _EPS).any():
        raise ValueError("a lathe profile must keep r > 0 except at its two ends")
    poles = [bool(r[0] < _EPS), bool(r[-1] < _EPS)]
    r[0] = 0.0 if poles[0] else r[0]
    r[-1] = 0.0 if poles[1] else r[-1]

    seg = np.diff(pts, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    seg_n = np.stack([seg[:, 1], -seg[:, 0]], 1) / seg_len[:, None]
    s = np.concatenate([[0.0], np.cumsum(seg_len)])
    w = np.concatenate([[0.0], np.cumsum(seg_len * profile.density)])
    v = w / w[-1]

    point_n = np.empty((n, 2))
    point_n[0], point_n[-1] = seg_n[0], seg_n[-1]
    point_n[1:-1] = _unit(seg_n[:-1] + seg_n[1:])
    # A smooth pole's normal is the axis itself, whichever way the last step leans.
    for end, k in ((0, 0), (1, -1)):
        if poles[end]:
            point_n[k] = (0.0, 1.0 if point_n[k][1] >= 0 else -1.0)

    rows: list[tuple[int, np.ndarray, bool]] = []
    in_row = np.empty(n, dtype=np.int64)
    out_row = np.empty(n, dtype=np.int64)
    for i in range(n):
        is_pole = (i == 0 and poles[0]) or (i == n - 1 and poles[1])
        if creases[i] and 0 < i < n - 1:
            in_row[i] = len(rows)
            rows.append((i, seg_n[i - 1], False))
            out_row[i] = len(rows)
            rows.append((i, seg_n[i], False))
        else:
            in_row[i] = out_row[i] = len(rows)
            rows.append((i, point_n[i], is_pole))

    N = segments
    u_ring = np.arange(N + 1) / N
    u_pole = (np.arange(N) + 0.5) / N  # one apex vertex per wedge keeps pole UVs non-degenerate
    P, NN, UV, offsets = [], [], [], []
    count = 0
    for i, nrm, is_pole in rows:
        u = u_pole if is_pole else u_ring
        th = theta0 + 2.0 * np.pi * u
        c, sn = np.cos(th), np.sin(th)
        P.append(np.stack([r[i] * c, r[i] * sn, np.full_like(u, z[i])], 1))
        NN.append(np.stack([nrm[0] * c, nrm[0] * sn, np.full_like(u, nrm[1])], 1))
        UV.append(np.stack([u, np.full_like(u, v[i])], 1))
        offsets.append(count)
        count += len(u)

    j = np.arange(N)
    tris = []
    for i in range(n - 1):
        a, b = out_row[i], in_row[i + 1]
        A, B = offsets[a], offsets[b]
        if rows[a][2] and rows[b][2]:
            raise ValueError("a lathe profile step cannot run along the axis")
        if rows[a][2]:
            tris.append(np.stack([A + j, B + j + 1, B + j], 1))
        elif rows[b][2]:
            tris.append(np.stack([A + j, A + j + 1, B + j], 1))
        else:
            tris.append(np.stack([A + j, A + j + 1, B + j + 1], 1))
            tris.append(np.stack([A + j, B + j + 1, B + j], 1))

    names = tuple(name for name, _ in profile.sections)
    starts = np.array([v[k] for _, k in profile.sections])
    geometry = Geometry(np.vstack(P), np.vstack(NN), np.vstack(UV), np.vstack(tris).astype(np.int64))
    return geometry, LatheLayout(r=r, z=z, s=s, v=v, section_names=names, section_start_v=starts, theta0=theta0)


def resample_polyline(points: np.ndarray, count: int) -> np.ndarray:
    """`count` points evenly spaced by arc length along a polyline."""
    p = np.asarray(points, dtype=np.float64)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-12])
    p = p[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], count)
    return np.stack([np.interp(t, s, p[:, k]) for k in range(p.shape[1])], 1)


def sweep_tube(
    path: np.ndarray,
    side: tuple[float, float, float],
    radii: tuple[float, float],
    segments: int = 32,
    v_range: float = 0.875,
) -> Geometry:
    """Closed tube of elliptical section along `path` (P, 3), with flat end caps.

    `side` is a direction perpendicular to the whole path (a planar path's plane normal) and
    `radii` = (radius in the path's plane, radius along `side`). The tube takes u around and
    v in [0, v_range] along the path; the caps get small discs below that.
    """
    path = np.asarray(path, dtype=np.float64)
    T = _unit(np.gradient(path, axis=0))
    S = np.asarray(side, dtype=np.float64)[None, :] - T * (T @ np.asarray(side, dtype=np.float64))[:, None]
    S = _unit(S)
    Nv = np.cross(S, T)  # (S, T, N) ordered so that the around-then-along winding faces out
    rn, rs = radii
    phi = 2.0 * np.pi * np.arange(segments + 1) / segments
    cp, sp = np.cos(phi)[None, :, None], np.sin(phi)[None, :, None]
    ring = path[:, None, :] + Nv[:, None, :] * (rn * cp) + S[:, None, :] * (rs * sp)
    nrm = _unit(Nv[:, None, :] * (cp / rn) + S[:, None, :] * (sp / rs))
    P, M = len(path), segments + 1
    seg_len = np.linalg.norm(np.diff(path, axis=0), axis=1)
    v = np.concatenate([[0.0], np.cumsum(seg_len)]) / seg_len.sum() * v_range
    uv = np.stack(np.broadcast_arrays((np.arange(M) / segments)[None, :], v[:, None]), -1)

    pos = [ring.reshape(-1, 3)]
    nor = [nrm.reshape(-1, 3)]
    uvs = [uv.reshape(-1, 2)]
    i, j = np.meshgrid(np.arange(P - 1), np.arange(segments), indexing="ij")
    a = (i * M + j).ravel()
    b = (i * M + j + 1).ravel()
    c = ((i + 1) * M + j + 1).ravel()
    d = ((i + 1) * M + j).ravel()
    tris = [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]

    count = P * M
    cap_r = (1.0 - v_range) * 0.4
    for k, sign, cu in ((0, -1.0, 0.25), (P - 1, 1.0, 0.75)):
        centre = count
        pos.append(np.vstack([path[k][None], ring[k, :segments]]))
        nor.append(np.repeat((sign * T[k])[None], segments + 1, 0))
        cv = v_range + (1.0 - v_range) * 0.5
        # Mirror the start disc so both caps keep the tube's UV orientation (no mirrored tangent frames).
        disc = np.stack([cu + cap_r * np.cos(phi[:segments]), cv + sign * cap_r * np.sin(phi[:segments])], 1)
        uvs.append(np.vstack([[cu, cv], disc]))
        rim = centre + 1 + np.arange(segments)
        nxt = centre + 1 + (np.arange(segments) + 1) % segments
        ctr = np.full(segments, centre)
        # cross(rim_j, rim_j+1) points along +T: the end cap keeps that order, the start cap flips it.
        tris.append(np.stack([ctr, rim, nxt], 1) if sign > 0 else np.stack([ctr, nxt, rim], 1))
        count += segments + 1
    return Geometry(np.vstack(pos), np.vstack(nor), np.vstack(uvs), np.vstack(tris).astype(np.int64))


# Box faces: (name, outward axis, sign, image-up axis, sign). Sides read upright with +Z up;
# right = up x normal, so texture columns run left-to-right as seen from outside.
BOX_FACES = (
    ("front", 1, -1.0, 2, 1.0),
    ("right", 0, 1.0, 2, 1.0),
    ("back", 1, 1.0, 2, 1.0),
    ("left", 0, -1.0, 2, 1.0),
    ("top", 2, 1.0, 1, 1.0),
    ("bottom", 2, -1.0, 1, 1.0),
)


def _box_axis_coords(h: float, radius: float, flat_steps: int, round_steps: int) -> np.ndarray:
    inner = h - radius
    flat = np.linspace(0.0, inner, flat_steps + 1)
    # Equal angles across the rounded band (q = inner + r tan a maps to angle a on the fillet).
    ang = np.linspace(0.0, np.pi / 4, round_steps + 1)[1:]
    pos = np.concatenate([flat, inner + radius * np.tan(ang)])
    pos[-1] = h  # exactly h, so neighbouring faces produce identical edge vertices
    return np.concatenate([-pos[::-1], pos[1:]])


def rounded_box(
    half_extents: tuple[float, float, float],
    radius: float,
    cells: dict[str, tuple[float, float, float, float]],
    flat_steps: int = 4,
    round_steps: int = 6,
) -> tuple[Geometry, dict[str, tuple[int, int]]]:
    """A box with fillets of `radius` on every edge and corner, one UV cell (u0, v0, u1, v1) per face.

    Each face's cell holds the whole face including half of each fillet; within a cell, face
    coordinates (a, b) in [-1, 1] run right and up as seen from outside. Returns the geometry and,
    per face, the (right axis, up axis) world indices for painters.
    """
    h = np.asarray(half_extents, dtype=np.float64)
    inner = h - radius
    coords = [_box_axis_coords(h[k], radius, flat_steps, round_steps) for k in range(3)]
    P, NN, UV, tris = [], [], [], []
    axes: dict[str, tuple[int, int]] = {}
    count = 0
    for name, n_ax, n_sign, up_ax, up_sign in BOX_FACES:
        n_vec = np.zeros(3)
        n_vec[n_ax] = n_sign
        up_vec = np.zeros(3)
        up_vec[up_ax] = up_sign
        right_vec = np.cross(up_vec, n_vec)
        r_ax = int(np.argmax(np.abs(right_vec)))
        r_sign = right_vec[r_ax]
        axes[name] = (r_ax, up_ax)
        ca, cb = coords[r_ax], coords[up_ax]
        A, B = np.meshgrid(ca, cb, indexing="xy")  # rows follow b, columns follow a
        q = np.zeros(A.shape + (3,))
        q[..., n_ax] = n_sign * h[n_ax]
        q[..., r_ax] = r_sign * A
        q[..., up_ax] = up_sign * B
        c = np.clip(q, -inner, inner)
        nrm = _unit(q - c)
        p = c + radius * nrm
        u0, v0, u1, v1 = cells[name]
        a_n, b_n = A / h[r_ax], B / h[up_ax]
        uv = np.stack([u0 + (a_n + 1) * 0.5 * (u1 - u0), v0 + (1 - b_n) * 0.5 * (v1 - v0)], -1)
        rows, cols = A.shape
        ii, jj = np.meshgrid(np.arange(rows - 1), np.arange(cols - 1), indexing="ij")
        k00 = count + ii * cols + jj
        k01 = k00 + 1  # +a
        k11 = k00 + cols + 1  # +a +b
        k10 = k00 + cols  # +b
        # right x up = outward, so (a, a+1, a+1 b+1) is counter-clockwise from outside.
        tris.append(np.stack([k00.ravel(), k01.ravel(), k11.ravel()], 1))
        tris.append(np.stack([k00.ravel(), k11.ravel(), k10.ravel()], 1))
        P.append(p.reshape(-1, 3))
        NN.append(nrm.reshape(-1, 3))
        UV.append(uv.reshape(-1, 2))
        count += rows * cols
    return Geometry(np.vstack(P), np.vstack(NN), np.vstack(UV), np.vstack(tris).astype(np.int64)), axes
