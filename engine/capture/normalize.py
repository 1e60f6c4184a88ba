"""Normalisation: move the posed capture into the model's world frame.

Object at the origin, inside the sphere of radius R (DESIGN.md §3), +Z up. From:
- up: the cameras' average up vector (a photographer holds the camera roughly upright),
- centre: where the optical axes converge (least squares), refined by the sparse points near it,
- support plane: most objects stand on a table or floor, or hang on a wall, whose sparse points
  would otherwise count as object (the radius would cover the floor and the masks would swallow
  it), so the dominant RANSAC plane that (nearly) every camera is in front of is found and its
  points, and those behind it, are set aside as background,
- radius: a high percentile of the remaining points' distances (the object), with a margin,
- heading: turned about +Z so the first camera looks along +Y, i.e. sees the object's front as the
  renderer's orbit azimuth 0 does.
The transform (source world -> normalised world, a similarity) is kept so exports can undo it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lirm.engine.cameras import Camera


@dataclass(frozen=True)
class NormalizeConfig:
    target_radius: float = 1.0  # R: the object ends inside this sphere
    fill: float = 0.85  # the estimated object radius maps to fill * R (room for estimation error)
    core_fraction: float = 0.6  # sparse points within this fraction of the median camera distance count as object
    radius_percentile: float = 95.0
    min_points: int = 20
    plane_cameras_fraction: float = 0.9  # of the cameras that must be in front of a support plane
    plane_tolerance: float = 0.01  # inlier distance, as a fraction of the median camera distance
    plane_min_fraction: float = 0.2  # of the points near the object, for a plane to count
    plane_iterations: int = 300
    # False: no support plane is looked for (a capture on a plain backdrop, whose only plane among
    # the points is the object's own base: plain_backdrop.py).
    find_plane: bool = True


@dataclass
class Normalization:
    world_from_source: np.ndarray  # 4x4 similarity
    center_source: np.ndarray  # object centre in the source frame
    radius_source: float  # estimated object radius in source units
    up_source: np.ndarray  # unit up direction in the source frame
    used_points: int  # sparse points that informed centre and radius (0 = cameras only)
    # The support plane in the normalised world as (unit normal, offset): n . x = offset; None if none.
    plane: tuple[np.ndarray, float] | None = None
    # How far off the plane a point must be to count as the object (normalised units): the plane's
    # own inlier noise. With 0 (older captures) half of a wall's points, the ones noise put just in
    # front of it, counted as the object: on the fox (a head mounted on a flowered wall) 1084 of 2015
    # points, and every automatic mask took in the wall.
    plane_margin: float = 0.0

    @property
    def scale(self) -> float:
        return float(np.cbrt(abs(np.linalg.det(self.world_from_source[:3, :3]))))

    def apply_to_camera(self, camera: Camera) -> Camera:
        return camera.moved_by(self.world_from_source)

    def apply_to_points(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return p @ self.world_from_source[:3, :3].T + self.world_from_source[:3, 3]

    def to_dict(self) -> dict:
        return {
            "world_from_source": self.world_from_source.tolist(),
            "center_source": self.center_source.tolist(),
            "radius_source": self.radius_source,
            "up_source": self.up_source.tolist(),
            "used_points": self.used_points,
            "plane": None if self.plane is None else [self.plane[0].tolist(), self.plane[1]],
            "plane_margin": self.plane_margin,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "Normalization":
        plane = d.get("plane")
        return cls(np.array(d["world_from_source"], dtype=np.float64), np.array(d["center_source"], dtype=np.float64),
                   float(d["radius_source"]), np.array(d["up_source"], dtype=np.float64), int(d["used_points"]),
                   None if plane is None else (np.array(plane[0], dtype=np.float64), float(plane[1])),
                   float(d.get("plane_margin", 0.0)))

    def object_point_mask(self, points_world: np.ndarray, radius: float) -> np.ndarray:
        """Which (normalised) points belong to the object: inside `radius` and above the support plane."""
        p = np.asarray(points_world, dtype=np.float64).reshape(-1, 3)
        keep = np.linalg.norm(p, axis=1) < radius
        if self.plane is not None:
            normal, offset = self.plane
            keep &= p @ normal - offset > self.plane_margin
        return keep


def is_floor(plane: tuple[np.ndarray, float] | None) -> bool:
    """Whether a support plane (unit normal, offset) is a floor under the object (normal near +Z in
    the normalised world) rather than a wall behind it."""
    return plane is not None and abs(float(np.asarray(plane[0])[2])) > 0.9


def axes_convergence(cameras: list[Camera]) -> np.ndarray:
    """The point closest (least squares) to every optical axis."""
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for cam in cameras:
        d = cam.forward / np.linalg.norm(cam.forward)
        p = np.eye(3) - np.outer(d, d)
        a += p
        b += p @ cam.center
    if np.linalg.cond(a) > 1e8:  # parallel axes (all cameras looking the same way): no convergence
        raise ValueError("the cameras' optical axes do not converge (all views look the same way)")
    return np.linalg.solve(a, b)


def estimate_normalization(cameras: dict[str, Camera], points: np.ndarray | None = None, config: NormalizeConfig = NormalizeConfig()) -> Normalization:
    if not cameras:
        raise ValueError("normalisation needs at least one posed camera")
    cams = [cameras[k] for k in sorted(cameras)]
    up = np.mean([c.up for c in cams], axis=0)
    if np.linalg.norm(up) < 1e-6:
        up = np.array([0.0, 0.0, 1.0])
    up /= np.linalg.norm(up)
    centres = np.array([c.center for c in cams])
    if len(cams) >= 2:
        try:
            center = axes_convergence(cams)
        except ValueError:
            center = centres.mean(axis=0) + cams[0].forward * np.linalg.norm(centres.std(axis=0) + 1e-9)
    else:
        center = None
    if center is None:  # one view: guess the object a median scene depth in front of it
        depth = 1.0
        if points is not None and len(points):
            _, z = cams[0].project(points)
            depth = float(np.median(z[z > 0])) if (z > 0).any() else 1.0
        center = cams[0].center + cams[0].forward * depth
    camera_distance = float(np.median(np.linalg.norm(centres - center, axis=1)))
    if camera_distance <= 0:
        camera_distance = 1.0

    used = 0
    radius = None
    plane_source = None
    if points is not None and len(points) >= config.min_points:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        near = p[np.linalg.norm(p - center, axis=1) < config.core_fraction * camera_distance]
        if config.find_plane:
            plane_source = find_support_plane(near, centres, config.plane_tolerance * camera_distance, config)
        if plane_source is not None:
            normal, offset = plane_source
            # Off the plane by more than three times the tolerance, on the cameras' side.
            near = near[near @ normal - offset > 3.0 * config.plane_tolerance * camera_distance]
            near = _drop_stragglers(near, normal)
        if len(near) >= config.min_points:
            if plane_source is not None:
                center, radius = _object_on_plane(near, plane_source, config, aim=center if len(cams) >= 2 else None,
                                                  camera_centres=centres)
            else:
                # Centre = middle of the robust extent of the object points.
                lo, hi = np.percentile(near, 5, axis=0), np.percentile(near, 95, axis=0)
                center = (lo + hi) / 2.0
                radius = float(np.percentile(np.linalg.norm(near - center, axis=1), config.radius_percentile))
            used = len(near)
    if radius is None or radius <= 0:
        # Cameras only: assume the object fills about half of the narrowest field of view.
        half_fov = np.deg2rad(min(min(c.fov_x_deg, c.fov_y_deg) for c in cams)) / 2.0
        radius = camera_distance * np.sin(half_fov) * 0.5

    rotation = _rotation_up_to_z(up)
    # Heading: the first camera's horizontal viewing direction becomes +Y.
    forward = rotation @ cams[0].forward
    heading = np.arctan2(forward[0], forward[1])  # angle from +Y toward +X
    c, s = np.cos(heading), np.sin(heading)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ rotation
    scale = config.fill * config.target_radius / radius
    transform = np.eye(4)
    transform[:3, :3] = scale * rotation
    transform[:3, 3] = -scale * rotation @ center
    plane = None
    if plane_source is not None:
        normal, offset = plane_source
        point_on_plane = normal * offset
        plane = (rotation @ normal, float((rotation @ normal) @ (transform[:3, :3] @ point_on_plane + transform[:3, 3])))
    margin = 3.0 * config.plane_tolerance * camera_distance * scale if plane is not None else 0.0
    return Normalization(transform, np.asarray(center, dtype=np.float64), float(radius), up, used, plane, margin)


def _drop_stragglers(points: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Keep the points whose distance from the group's middle, measured along the plane, is within
    three times the median: a few floor points that noise lifted off the plane would otherwise set
    the radius of a slim object (a bottle: 66 object points, the radius doubled)."""
    if len(points) < 4:
        return points
    flat = points - np.outer(points @ normal, normal)
    middle = np.median(flat, axis=0)
    distance = np.linalg.norm(flat - middle, axis=1)
    return points[distance <= 3.0 * max(float(np.median(distance)), 1e-12)]


def _object_on_plane(points: np.ndarray, plane: tuple[np.ndarray, float], config: NormalizeConfig,
                     aim: np.ndarray | None = None, camera_centres: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """An object standing on the plane reaches down to it, however few points its base has: the
    centre sits half-way between the plane and the object's top, the radius covers both.

    Along the plane, the centre is where the cameras aim (`aim`, their axes' convergence) when that
    lies among the object's points: sparse points come mostly from the sides the cameras see best
    and most textured, so their middle can sit half an object off (the demo mug: 0.5 R in one run
    of three, and masks cut in half). The photographer centring the object is the steadier cue, and
    a certain one when the cameras go round it (no gap of 180 degrees in their directions from it)."""
    normal, offset = plane
    heights = points @ normal - offset
    top = float(np.percentile(heights, 98))
    flat = points - np.outer(heights, normal)  # feet on the plane
    lo, hi = np.percentile(flat, 5, axis=0), np.percentile(flat, 95, axis=0)
    foot = (lo + hi) / 2.0
    if aim is not None:
        aim_foot = aim - ((aim @ normal) - offset) * normal
        spread = float(np.percentile(np.linalg.norm(flat - np.median(flat, axis=0), axis=1), 95))
        surrounded = camera_centres is not None and _surrounds(camera_centres, aim_foot, normal)
        if surrounded or np.linalg.norm(aim_foot - np.median(flat, axis=0)) <= max(spread, 1e-12):
            foot = aim_foot
    foot -= ((foot @ normal) - offset) * normal  # back onto the plane exactly
    center = foot + normal * (top / 2.0)
    radius = max(float(np.percentile(np.linalg.norm(points - center, axis=1), config.radius_percentile)), top / 2.0)
    return center, radius


def _surrounds(camera_centres: np.ndarray, point: np.ndarray, normal: np.ndarray) -> bool:
    """Whether the cameras' directions from `point`, seen along the plane's normal, leave no gap of
    180 degrees or more (an orbit, not a sweep from one side)."""
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    d = camera_centres - point
    angles = np.sort(np.arctan2(d @ v, d @ u))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2.0 * np.pi]))
    return len(angles) >= 3 and float(gaps.max()) < np.pi


def find_support_plane(points: np.ndarray, camera_centres: np.ndarray, tolerance: float, config: NormalizeConfig,
                       seed: int = 0) -> tuple[np.ndarray, float] | None:
    """The largest plane among `points` that (nearly) every camera looks at from the same side: a
    table under the object or a wall behind it (RANSAC, then a least-squares refit). Returned as
    (unit normal pointing toward the cameras, offset). None when no plane holds enough points."""
    if len(points) < max(config.min_points, 3):
        return None
    rng = np.random.default_rng(seed)

    def cameras_in_front(n: np.ndarray, d: float) -> float:
        side = camera_centres @ n - d
        return max(float(np.mean(side > 0)), float(np.mean(side < 0)))

    best, best_count = None, 0
    for _ in range(config.plane_iterations):
        a, b, c = points[rng.choice(len(points), 3, replace=False)]
        n = np.cross(b - a, c - a)
        length = np.linalg.norm(n)
        if length < 1e-12:
            continue
        n /= length
        inliers = np.abs((points - a) @ n) < tolerance
        count = int(inliers.sum())
        if count > best_count and cameras_in_front(n, float(n @ a)) >= config.plane_cameras_fraction:
            best, best_count = inliers, count
    if best is None or best_count < config.plane_min_fraction * len(points):
        return None
    q = points[best]
    centroid = q.mean(axis=0)
    normal = np.linalg.svd(q - centroid)[2][-1]
    if np.mean(camera_centres @ normal - normal @ centroid > 0) < 0.5:
        normal = -normal
    return normal, float(normal @ centroid)


def _rotation_up_to_z(up: np.ndarray) -> np.ndarray:
    """The smallest rotation taking `up` to +Z."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(up, z)
    c = float(np.dot(up, z))
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)
