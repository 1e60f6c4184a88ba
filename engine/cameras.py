"""Pinhole cameras (OpenCV convention), pose conversions, pixel rays and Plücker coordinates.

Conventions (DESIGN.md section 3), fixed for the whole project:

- Camera frame is OpenCV: x right, y down, z forward. Poses are 4x4 camera-to-world (`c2w`, float64).
- Intrinsics fx, fy, cx, cy are in pixels of a continuous image plane on which pixel (i, j)
  (column i, row j) covers [i, i+1] x [j, j+1], so its centre is at (i + 0.5, j + 0.5). A centred
  principal point is therefore (W / 2, H / 2). Projection is the usual u = fx * x + cx.
- Optional lens distortion follows OpenCV's model with coefficients k1, k2, p1, p2[, k3[, k4, k5, k6]]
  (the 8-coefficient form is the rational model). It acts on normalized camera coordinates, so a
  crop or resize never changes it.
- World is right-handed with +Z up.
- The Plücker ray of a pixel is (d, o x d): d the unit world direction, o the camera centre.

Blender/NeRF/nerfstudio (OpenGL: x right, y up, z backward) and COLMAP (world-to-camera, quaternion
qw qx qy qz) poses are converted at the I/O boundary with the functions below, nowhere else.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

__all__ = [
    "Camera",
    "look_at",
    "orbit_camera",
    "orbit_cameras",
    "nearest_cameras",
    "distance_to_cover_sphere",
    "fov_to_focal",
    "focal_to_fov",
    "opengl_to_opencv_c2w",
    "opencv_to_opengl_c2w",
    "colmap_to_c2w",
    "c2w_to_colmap",
    "qvec_to_rotmat",
    "rotmat_to_qvec",
    "plucker_rays",
    "distort_normalized",
    "undistort_normalized",
]

# Flipping the camera's y and z axes turns OpenGL (y up, z back) into OpenCV (y down, z forward)
# and back; it is its own inverse.
_GL_CV_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])

# Tolerance on c2w being a rigid transform: loose enough for poses stored as float32 or printed
# with few digits in JSON files, tight enough to catch a scale or a projection matrix by mistake.
_RIGID_TOL = 1e-3

_DISTORTION_SIZES = (4, 5, 8)
_DISTORTION_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")


# --------------------------------------------------------------------------------------------------
# Focal length and field of view


def fov_to_focal(fov_deg: float, size_px: float) -> float:
    """Focal length in pixels giving a full field of view `fov_deg` across `size_px` pixels."""
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"field of view must be in (0, 180) degrees, got {fov_deg}")
    return 0.5 * size_px / math.tan(math.radians(fov_deg) * 0.5)


def focal_to_fov(focal_px: float, size_px: float) -> float:
    """Full field of view in degrees across `size_px` pixels for a centred principal point."""
    if focal_px <= 0.0:
        raise ValueError(f"focal length must be positive, got {focal_px}")
    return math.degrees(2.0 * math.atan(0.5 * size_px / focal_px))


def distance_to_cover_sphere(radius: float, fov_deg: float) -> float:
    """Smallest camera distance at which a sphere of `radius` fits inside a field of view `fov_deg`.

    The cone of half-angle fov/2 is tangent to the sphere when sin(fov/2) = radius / distance;
    pass the FoV of the image's smaller side to be sure the whole sphere is visible.
    """
    if not 0.0 < fov_deg < 180.0:
        raise ValueError(f"field of view must be in (0, 180) degrees, got {fov_deg}")
    return radius / math.sin(math.radians(fov_deg) * 0.5)


# --------------------------------------------------------------------------------------------------
# Pose conventions


def opengl_to_opencv_c2w(c2w_gl: np.ndarray) -> np.ndarray:
    """OpenGL/Blender/NeRF camera-to-world (x right, y up, z back) -> OpenCV. Works on (..., 4, 4)."""
    c2w_gl = np.asarray(c2w_gl, dtype=np.float64)
    return c2w_gl @ _GL_CV_FLIP


def opencv_to_opengl_c2w(c2w: np.ndarray) -> np.ndarray:
    """OpenCV camera-to-world -> OpenGL/Blender/NeRF (x right, y up, z back). Works on (..., 4, 4)."""
    c2w = np.asarray(c2w, dtype=np.float64)
    return c2w @ _GL_CV_FLIP


def qvec_to_rotmat(qvec: Sequence[float]) -> np.ndarray:
    """Unit quaternion (qw, qx, qy, qz), COLMAP's order, -> 3x3 rotation matrix."""
    q = np.asarray(qvec, dtype=np.float64)
    n = np.linalg.norm(q)
    if q.shape != (4,) or not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"a quaternion must be 4 finite numbers (qw, qx, qy, qz), got {qvec!r}")
    w, x, y, z = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotmat_to_qvec(R: np.ndarray) -> np.ndarray:
    """3x3 rotation -> unit quaternion (qw, qx, qy, qz) with qw >= 0 (q and -q are one rotation)."""
    R = np.asarray(R, dtype=np.float64)
    # Shepperd's method: divide by the largest of the four candidates, so it never loses precision.
    t = np.trace(R)
    cands = [t, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * math.sqrt(max(1.0 + t, 0.0))
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(max(1.0 + R[0, 0] - R[1, 1] - R[2, 2], 0.0))
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(max(1.0 - R[0, 0] + R[1, 1] - R[2, 2], 0.0))
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(max(1.0 - R[0, 0] - R[1, 1] + R[2, 2], 0.0))
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def colmap_to_c2w(R_or_qvec: np.ndarray | Sequence[float], t: Sequence[float]) -> np.ndarray:
    """COLMAP world-to-camera (rotation as 3x3 or quaternion qw qx qy qz, translation t) -> c2w.

    COLMAP's camera frame is already OpenCV's; only the direction of the transform changes.
    """
    R = np.asarray(R_or_qvec, dtype=np.float64)
    if R.shape == (4,):
        R = qvec_to_rotmat(R)
    elif R.shape != (3, 3):
        raise ValueError(f"expected a 3x3 rotation or a (qw, qx, qy, qz) quaternion, got shape {R.shape}")
    t = np.asarray(t, dtype=np.float64).reshape(3)
    c2w = np.eye(4)
    c2w[:3, :3] = R.T
    c2w[:3, 3] = -R.T @ t
    return c2w


def c2w_to_colmap(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV c2w -> COLMAP (qvec (qw, qx, qy, qz) with qw >= 0, t) of the world-to-camera pose."""
    c2w = np.asarray(c2w, dtype=np.float64)
    R = c2w[:3, :3].T
    t = -R @ c2w[:3, 3]
    return rotmat_to_qvec(R), t


def _normalize(v: np.ndarray, what: str) -> np.ndarray:
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"{what} has zero length")
    return v / n


def look_at(
    eye: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)
) -> np.ndarray:
    """OpenCV c2w of a camera at `eye` looking at `target`, upright with respect to `up`.

    z = normalize(target - eye), x = normalize(z x up), y = z x x (pointing down the image), so
    `up` projects upward in the image.
    """
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    target = np.asarray(target, dtype=np.float64).reshape(3)
    up = _normalize(np.asarray(up, dtype=np.float64).reshape(3), "look_at: up")
    z = _normalize(target - eye, "look_at: target - eye (eye and target coincide)")
    x = np.cross(z, up)
    # sin of the angle between up and the view direction; below this the image roll is undefined.
    if np.linalg.norm(x) < 1e-6:
        raise ValueError(
            f"look_at: up {tuple(up)} is parallel to the view direction {tuple(z)}; "
            "the image orientation is undefined, pass a different up vector"
        )
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    return c2w


# --------------------------------------------------------------------------------------------------
# Lens distortion on normalized camera coordinates (OpenCV model)


def _check_distortion(dist: Any) -> np.ndarray | None:
    if dist is None:
        return None
    d = np.array(dist, dtype=np.float64).reshape(-1)
    if d.size not in _DISTORTION_SIZES:
        raise ValueError(
            f"distortion must have 4, 5 or 8 OpenCV coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]), "
            f"got {d.size}"
        )
    if not np.all(np.isfinite(d)):
        raise ValueError(f"distortion coefficients must be finite, got {d.tolist()}")
    # An all-zero model is the pinhole: keep one representation so `distortion is None` means it.
    return None if not np.any(d) else d


def _coeffs(dist: np.ndarray) -> tuple[float, ...]:
    full = np.zeros(8)
    full[: dist.size] = dist
    return tuple(float(c) for c in full)


def distort_normalized(xy: np.ndarray, dist: np.ndarray | None) -> np.ndarray:
    """Apply OpenCV distortion to undistorted normalized coordinates (..., 2) (x = X/Z, y = Y/Z)."""
    xy = np.asarray(xy, dtype=np.float64)
    if dist is None:
        return xy.copy()
    k1, k2, p1, p2, k3, k4, k5, k6 = _coeffs(np.asarray(dist))
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.stack([xd, yd], axis=-1)


def undistort_normalized(
    xy_d: np.ndarray, dist: np.ndarray | None, iterations: int = 20, tol: float = 1e-14
) -> np.ndarray:
    """Invert `distort_normalized` (..., 2) by vectorised Newton iterations.

    Newton with the analytic Jacobian rather than OpenCV's fixed-point loop: it converges to machine
    precision in a few steps, which the crop-keeps-every-ray guarantee needs. Points outside the
    region where the model is invertible keep the best estimate found.
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    if dist is None:
        return xy_d.copy()
    k1, k2, p1, p2, k3, k4, k5, k6 = _coeffs(np.asarray(dist))
    xd, yd = xy_d[..., 0], xy_d[..., 1]
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        a = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        b = 1 + r2 * (k4 + r2 * (k5 + r2 * k6))
        da = k1 + r2 * (2 * k2 + 3 * k3 * r2)
        db = k4 + r2 * (2 * k5 + 3 * k6 * r2)
        radial = a / b
        dradial = (da * b - a * db) / (b * b)  # d radial / d r2
        fx = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) - xd
        fy = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y - yd
        jxx = radial + 2 * x * x * dradial + 2 * p1 * y + 6 * p2 * x
        jyy = radial + 2 * y * y * dradial + 6 * p1 * y + 2 * p2 * x
        jxy = 2 * x * y * dradial + 2 * p1 * x + 2 * p2 * y  # the Jacobian is symmetric
        det = jxx * jyy - jxy * jxy
        ok = np.abs(det) > 1e-12
        safe = np.where(ok, det, 1.0)
        x = x - np.where(ok, (jyy * fx - jxy * fy) / safe, 0.0)
        y = y - np.where(ok, (jxx * fy - jxy * fx) / safe, 0.0)
        if max(np.max(np.abs(fx), initial=0.0), np.max(np.abs(fy), initial=0.0)) < tol:
            break
    return np.stack([x, y], axis=-1)


def plucker_rays(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(..., 6) Plücker coordinates [d, o x d] of rays; `directions` must already be unit length."""
    origins = np.asarray(origins, dtype=np.float64)
    directions = np.asarray(directions, dtype=np.float64)
    origins = np.broadcast_to(origins, directions.shape)
    return np.concatenate([directions, np.cross(origins, directions)], axis=-1)


# --------------------------------------------------------------------------------------------------
# The camera


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera with optional OpenCV distortion, in the project's conventions (module doc).

    Frozen: derive new cameras with `with_pose`, `scaled`, `crop_resize` or `dataclasses.replace`;
    the arrays are private copies and must not be modified in place. `==` is identity; compare
    values with `allclose`.
    """

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    c2w: np.ndarray
    distortion: np.ndarray | None = None

    def __post_init__(self) -> None:
        # Normalise types once so every consumer (and JSON) sees Python ints/floats and float64 arrays.
        set_ = object.__setattr__
        w, h = int(self.width), int(self.height)
        if w != self.width or h != self.height or w < 1 or h < 1:
            raise ValueError(f"image size must be positive integers, got {self.width} x {self.height}")
        set_(self, "width", w)
        set_(self, "height", h)
        for name in ("fx", "fy", "cx", "cy"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise ValueError(f"{name} must be finite, got {v}")
            set_(self, name, v)
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"focal lengths must be positive, got fx={self.fx}, fy={self.fy}")
        c2w = np.array(self.c2w, dtype=np.float64)
        if c2w.shape == (3, 4):
            c2w = np.vstack([c2w, [0.0, 0.0, 0.0, 1.0]])
        if c2w.shape != (4, 4) or not np.all(np.isfinite(c2w)):
            raise ValueError(f"c2w must be a finite 4x4 (or 3x4) matrix, got shape {c2w.shape}")
        R = c2w[:3, :3]
        if (
            np.abs(c2w[3] - [0.0, 0.0, 0.0, 1.0]).max() > _RIGID_TOL
            or np.abs(R.T @ R - np.eye(3)).max() > _RIGID_TOL
            or np.linalg.det(R) < 0
        ):
            raise ValueError(
                "c2w must be a rigid camera-to-world transform (orthonormal rotation with det +1, "
                f"last row 0 0 0 1), got\n{c2w}"
            )
        set_(self, "c2w", c2w)
        set_(self, "distortion", _check_distortion(self.distortion))

    # ---- constructors --------------------------------------------------------------------------

    @classmethod
    def from_fov(
        cls,
        width: int,
        height: int,
        fov_deg: float,
        c2w: np.ndarray,
        axis: str = "x",
        distortion: np.ndarray | None = None,
    ) -> "Camera":
        """Square pixels, centred principal point, full FoV `fov_deg` along `axis`.

        axis: "x" (image width), "y" (image height) or "min" (the smaller image side, so a sphere
        at `distance_to_cover_sphere(r, fov_deg)` fits whatever the aspect ratio).
        """
        sizes = {"x": width, "y": height, "min": min(width, height)}
        if axis not in sizes:
            raise ValueError(f'axis must be "x", "y" or "min", got {axis!r}')
        f = fov_to_focal(fov_deg, sizes[axis])
        return cls(width, height, f, f, width / 2.0, height / 2.0, c2w, distortion)

    @classmethod
    def from_opengl(
        cls,
        c2w_gl: np.ndarray,
        width: int,
        height: int,
        fx: float,
        fy: float | None = None,
        cx: float | None = None,
        cy: float | None = None,
        distortion: np.ndarray | None = None,
    ) -> "Camera":
        """From an OpenGL/Blender camera-to-world (x right, y up, z back); fy defaults to fx and the
        principal point to the image centre."""
        return cls(
            width,
            height,
            fx,
            fx if fy is None else fy,
            width / 2.0 if cx is None else cx,
            height / 2.0 if cy is None else cy,
            opengl_to_opencv_c2w(c2w_gl),
            distortion,
        )

    @classmethod
    def from_nerf(
        cls, transform_matrix: np.ndarray, camera_angle_x: float, width: int, height: int
    ) -> "Camera":
        """From a NeRF (Blender synthetic) frame: OpenGL `transform_matrix` and `camera_angle_x`, the
        horizontal FoV in RADIANS as those files store it; square pixels, centred principal point."""
        f = 0.5 * width / math.tan(0.5 * float(camera_angle_x))
        return cls.from_opengl(transform_matrix, width, height, f)

    # ---- derived quantities --------------------------------------------------------------------

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def w2c(self) -> np.ndarray:
        """4x4 world-to-camera (the exact inverse of c2w)."""
        return np.linalg.inv(self.c2w)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, (3,)."""
        return self.c2w[:3, 3].copy()

    @property
    def rotation(self) -> np.ndarray:
        """3x3 camera-to-world rotation; its columns are the camera's x, y, z axes in the world."""
        return self.c2w[:3, :3].copy()

    @property
    def right(self) -> np.ndarray:
        """World direction of the image's +x (right)."""
        return self.c2w[:3, 0].copy()

    @property
    def up(self) -> np.ndarray:
        """World direction of the image's up (minus the OpenCV y axis)."""
        return -self.c2w[:3, 1]

    @property
    def forward(self) -> np.ndarray:
        """World direction of the optical axis (the OpenCV z axis)."""
        return self.c2w[:3, 2].copy()

    @property
    def fov_x_deg(self) -> float:
        """Horizontal FoV in degrees between the left and right image edges (pinhole, distortion
        ignored); an off-centre principal point is accounted for."""
        return math.degrees(math.atan(self.cx / self.fx) + math.atan((self.width - self.cx) / self.fx))

    @property
    def fov_y_deg(self) -> float:
        """Vertical FoV in degrees between the top and bottom image edges (see fov_x_deg)."""
        return math.degrees(math.atan(self.cy / self.fy) + math.atan((self.height - self.cy) / self.fy))

    # ---- derived cameras -----------------------------------------------------------------------

    def with_pose(self, c2w: np.ndarray) -> "Camera":
        """Same intrinsics, another OpenCV camera-to-world pose."""
        return dataclasses.replace(self, c2w=c2w)

    def moved_by(self, similarity: np.ndarray) -> "Camera":
        """The same camera in a world moved by `similarity` (4x4: a rotation times a uniform scale, and a
        translation): it sees every moved point where it saw the point before. The scale moves the
        centre only; the rotation stays orthonormal."""
        similarity = np.asarray(similarity, dtype=np.float64)
        c2w = similarity @ self.c2w
        c2w[:3, :3] /= float(np.cbrt(abs(np.linalg.det(similarity[:3, :3]))))
        return self.with_pose(c2w)

    def crop_resize(
        self, x0: float, y0: float, crop_w: float, crop_h: float, out_w: int, out_h: int
    ) -> "Camera":
        """The camera of a crop of this image resized to out_w x out_h.

        The crop starts at pixel corner (x0, y0) and spans crop_w x crop_h pixels of this image; all
        may be fractional and the crop may extend past the image. Output pixel (i, j) sees exactly
        the ray this camera has at x = x0 + (i + 0.5) * crop_w / out_w, y = y0 + (j + 0.5) * crop_h /
        out_h. Distortion acts on normalized coordinates and is therefore unchanged.
        """
        if crop_w <= 0 or crop_h <= 0:
            raise ValueError(f"crop size must be positive, got {crop_w} x {crop_h}")
        sx, sy = out_w / crop_w, out_h / crop_h
        return dataclasses.replace(
            self,
            width=out_w,
            height=out_h,
            fx=self.fx * sx,
            fy=self.fy * sy,
            cx=(self.cx - x0) * sx,
            cy=(self.cy - y0) * sy,
        )

    def resized(self, width: int, height: int) -> "Camera":
        """The whole image resized to width x height (rays kept exactly, even for a changed aspect)."""
        return self.crop_resize(0.0, 0.0, self.width, self.height, width, height)

    def scaled(self, factor: float) -> "Camera":
        """The whole image resized by `factor`; sizes are rounded and the intrinsics follow the
        rounded sizes so that every pixel keeps its ray."""
        w, h = round(self.width * factor), round(self.height * factor)
        if w < 1 or h < 1:
            raise ValueError(f"scale factor {factor} makes an empty image from {self.width} x {self.height}")
        return self.resized(w, h)

    # ---- rays and projection -------------------------------------------------------------------

    def rays_at(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World rays through continuous pixel coordinates `xy` (..., 2) (pixel centres at +0.5).

        Returns (origins (..., 3), unit directions (..., 3)). With distortion, the observed pixel is
        undistorted first, so the ray is the one the real lens maps to that pixel.
        """
        xy = np.asarray(xy, dtype=np.float64)
        if xy.shape[-1:] != (2,):
            raise ValueError(f"pixel coordinates must have shape (..., 2), got {xy.shape}")
        n = np.stack([(xy[..., 0] - self.cx) / self.fx, (xy[..., 1] - self.cy) / self.fy], axis=-1)
        n = undistort_normalized(n, self.distortion)
        d_cam = np.concatenate([n, np.ones(n.shape[:-1] + (1,))], axis=-1)
        d = d_cam @ self.c2w[:3, :3].T
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(self.c2w[:3, 3], d.shape).copy()
        return o, d

    def pixel_grid(self) -> np.ndarray:
        """(H, W, 2) continuous coordinates of every pixel centre; [j, i] = (i + 0.5, j + 0.5)."""
        xs = np.arange(self.width, dtype=np.float64) + 0.5
        ys = np.arange(self.height, dtype=np.float64) + 0.5
        gx, gy = np.meshgrid(xs, ys, indexing="xy")
        return np.stack([gx, gy], axis=-1)

    def pixel_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """(origins (H, W, 3), unit directions (H, W, 3)) in world space at every pixel centre."""
        return self.rays_at(self.pixel_grid())

    def plucker(self) -> np.ndarray:
        """(H, W, 6) float32 Plücker rays [d, o x d] of every pixel centre."""
        o, d = self.pixel_rays()
        return plucker_rays(o, d).astype(np.float32)

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points (..., 3) to continuous pixel coordinates, applying distortion.

        Returns (xy (..., 2), depth (...)), depth being the camera-space z (not the Euclidean
        distance). Points with depth <= 0 are behind the camera: their xy is meaningless (and
        inf/nan at depth 0), so mask them with depth > 0.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {p.shape}")
        w2c = self.w2c
        pc = p @ w2c[:3, :3].T + w2c[:3, 3]
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            n = pc[..., :2] / z[..., None]
        n = distort_normalized(n, self.distortion)
        xy = np.stack([n[..., 0] * self.fx + self.cx, n[..., 1] * self.fy + self.cy], axis=-1)
        return xy, z

    # ---- comparison and serialisation ----------------------------------------------------------

    def allclose(self, other: "Camera", atol: float = 1e-9) -> bool:
        """Same size and, within `atol`, the same intrinsics, pose and distortion."""
        if (self.width, self.height) != (other.width, other.height):
            return False
        a = np.array([self.fx, self.fy, self.cx, self.cy])
        b = np.array([other.fx, other.fy, other.cx, other.cy])
        da = np.zeros(8) if self.distortion is None else np.asarray(_coeffs(self.distortion))
        db = np.zeros(8) if other.distortion is None else np.asarray(_coeffs(other.distortion))
        return bool(
            np.allclose(a, b, rtol=0, atol=atol)
            and np.allclose(self.c2w, other.c2w, rtol=0, atol=atol)
            and np.allclose(da, db, rtol=0, atol=atol)
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict in nerfstudio's transforms.json frame format.

        Keys: w, h, fl_x, fl_y, cx, cy, camera_model, k1, k2, p1, p2 (always), k3 (5+ coefficients),
        k4, k5, k6 (8 coefficients) and `transform_matrix`: the camera-to-world in the OpenGL /
        nerfstudio convention (x right, y up, z backward), world axes unchanged. camera_model is
        "OPENCV", or "FULL_OPENCV" (COLMAP's name) for the 8-coefficient rational model, because
        nerfstudio's own "k4" means an r^8 term and must not be confused with OpenCV's k4.
        """
        d: dict[str, Any] = {
            "w": self.width,
            "h": self.height,
            "fl_x": self.fx,
            "fl_y": self.fy,
            "cx": self.cx,
            "cy": self.cy,
        }
        coeffs = np.zeros(4) if self.distortion is None else self.distortion
        d["camera_model"] = "FULL_OPENCV" if coeffs.size == 8 else "OPENCV"
        for name, value in zip(_DISTORTION_NAMES, coeffs):
            d[name] = float(value)
        d["transform_matrix"] = opencv_to_opengl_c2w(self.c2w).tolist()
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Camera":
        """Inverse of `to_dict`; also reads nerfstudio/NeRF files.

        For a transforms.json whose intrinsics are shared at the top level, pass {**top, **frame}.
        Missing fl_x falls back to camera_angle_x (radians), missing fl_y to fl_x, a missing
        principal point to the image centre. Fisheye and other non-pinhole models raise ValueError.
        """
        model = str(d.get("camera_model", "OPENCV")).upper()
        if model not in ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "FULL_OPENCV"):
            raise ValueError(f"camera_model {model!r} is not supported (only pinhole with OpenCV distortion)")
        try:
            w, h = int(d["w"]), int(d["h"])
            if "fl_x" in d:
                fx = float(d["fl_x"])
            else:
                fx = 0.5 * w / math.tan(0.5 * float(d["camera_angle_x"]))
            tm = np.asarray(d["transform_matrix"], dtype=np.float64)
        except KeyError as e:
            raise ValueError(f"camera dict lacks {e.args[0]!r} (needs w, h, fl_x or camera_angle_x, "
                             "transform_matrix)") from None
        fy = float(d.get("fl_y", fx))
        cx = float(d.get("cx", w / 2.0))
        cy = float(d.get("cy", h / 2.0))
        names = _DISTORTION_NAMES if model == "FULL_OPENCV" else _DISTORTION_NAMES[:5]
        if model != "FULL_OPENCV" and float(d.get("k4", 0.0)) != 0.0:
            raise ValueError(
                "k4 is set but camera_model is not FULL_OPENCV: nerfstudio's k4 (an r^8 term) is not "
                "OpenCV's rational k4 and is not supported"
            )
        coeffs = [float(d.get(name, 0.0)) for name in names]
        if model == "FULL_OPENCV":
            dist = coeffs
        elif coeffs[4] != 0.0:
            dist = coeffs[:5]
        else:
            dist = coeffs[:4]
        if tm.shape == (3, 4):
            tm = np.vstack([tm, [0.0, 0.0, 0.0, 1.0]])
        return cls(w, h, fx, fy, cx, cy, opengl_to_opencv_c2w(tm), dist)


# --------------------------------------------------------------------------------------------------
# Cameras back from rays


def _cross_matrices(v: np.ndarray) -> np.ndarray:
    """(N, 3) -> (N, 3, 3): [v]x with [v]x @ u = v x u."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], -1), np.stack([v[:, 2], z, -v[:, 0]], -1),
                     np.stack([-v[:, 1], v[:, 0], z], -1)], axis=1)


def camera_from_plucker(plucker: np.ndarray, tolerance_deg: float = 0.05, max_pixels: int = 4096) -> Camera:
    """The pinhole camera whose pixel-centre rays are `plucker` (H, W, 6) [d, o x d]: the inverse of
    `Camera.plucker()`, for code that is handed only what the network sees (a crop keeps its rays, so
    a crop's camera comes back with its own intrinsics).

    The centre o lies on every ray (o x d = m: linear in o, least squares). The directions are
    M (x, y, 1) up to a positive scale with M = R K^-1 (d x M x = 0: linear in M, the smallest singular
    vector), and the QR decomposition of M splits it into the rotation R and the upper-triangular K^-1.
    Raises ValueError when no undistorted pinhole reproduces the rays to within `tolerance_deg`
    (lens distortion, rays of several cameras, noise).
    """
    rays = np.asarray(plucker, np.float64)
    if rays.ndim != 3 or rays.shape[-1] != 6 or rays.shape[0] < 2 or rays.shape[1] < 2:
        raise ValueError(f"Plücker rays must have shape (H, W, 6) with H, W >= 2, got {rays.shape}")
    h, w = rays.shape[:2]
    stride = max(1, int(math.ceil(math.sqrt(h * w / max_pixels))))  # enough pixels for a 3x3 fit
    ys, xs = np.mgrid[0:h:stride, 0:w:stride]
    d, m = rays[ys, xs, :3].reshape(-1, 3), rays[ys, xs, 3:].reshape(-1, 3)
    if not (np.isfinite(d).all() and np.isfinite(m).all()):
        raise ValueError("Plücker rays contain NaN or inf")
    norms = np.linalg.norm(d, axis=1, keepdims=True)
    if norms.min() < 1e-9:
        raise ValueError("Plücker rays contain zero directions")
    d = d / norms
    m = m / norms
    cross_d = _cross_matrices(d)
    centre = np.linalg.lstsq(cross_d.reshape(-1, 3), -m.reshape(-1), rcond=None)[0]  # d x o = -(o x d)
    # Pixel centres, normalised for conditioning: xn = T x.
    scale = 2.0 / max(w, h)
    T = np.array([[scale, 0.0, -w * scale / 2], [0.0, scale, -h * scale / 2], [0.0, 0.0, 1.0]])
    x = np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5, np.ones(xs.size)], axis=-1) @ T.T
    system = np.einsum("nij,nk->nijk", cross_d, x).reshape(-1, 9)  # rows of d x (Mn x) = 0 in vec(Mn)
    M = np.linalg.svd(system, full_matrices=False)[2][-1].reshape(3, 3) @ T
    if np.median(np.einsum("ij,nj,ni->n", M, x @ np.linalg.inv(T).T, d)) < 0:
        M = -M  # the scale's sign: directions point forward, as the rays do
    rotation, inverse_k = np.linalg.qr(M)
    signs = np.sign(np.diag(inverse_k))
    signs[signs == 0] = 1.0
    rotation, inverse_k = rotation * signs, signs[:, None] * inverse_k
    if np.linalg.det(rotation) < 0 or inverse_k[2, 2] <= 0:
        raise ValueError("the rays are mirrored: no right-handed pinhole camera makes them")
    K = np.linalg.inv(inverse_k / inverse_k[2, 2])
    c2w = np.eye(4)
    c2w[:3, :3], c2w[:3, 3] = rotation, centre
    camera = Camera(w, h, K[0, 0], K[1, 1], K[0, 2], K[1, 2], c2w)
    # The camera has no skew: check what it gives back against what it was made from.
    o, back = camera.rays_at(np.stack([xs.ravel() + 0.5, ys.ravel() + 0.5], -1))
    angle = np.degrees(np.arccos(np.clip(np.sum(back * d, axis=1), -1.0, 1.0)))
    offset = np.linalg.norm(np.cross(o, d) - m, axis=1)  # how far the rays pass from the centre
    size = max(float(np.linalg.norm(centre)), 1.0)
    if angle.max() > tolerance_deg or offset.max() > np.radians(tolerance_deg) * size:
        raise ValueError(f"the rays do not come from one pinhole camera (worst direction error {angle.max():.3f}°, "
                         f"ray offset {offset.max():.2e}); undistorted crops of one photo do")
    return camera


# --------------------------------------------------------------------------------------------------
# Orbits around a target (synthetic data, previews, guidance)


def orbit_camera(
    azimuth_deg: float,
    elevation_deg: float,
    distance: float,
    width: int,
    height: int,
    fov_deg: float,
    target: Sequence[float] = (0.0, 0.0, 0.0),
    axis: str = "x",
) -> Camera:
    """A camera on a sphere around `target`, looking at it, upright (+Z up).

    Azimuth 0 puts the camera on the -Y side looking toward +Y (the front of a glTF model once
    converted to +Z up faces -Y); azimuth 90 puts it on +X, i.e. the camera moves counter-clockwise
    seen from above. Positive elevation is above the target. `fov_deg` is along `axis` (see
    Camera.from_fov). At elevation +-90 the image's up is the horizontal direction the camera
    would face at that azimuth, so the poles are well defined and continuous with the orbit.
    """
    if distance <= 0:
        raise ValueError(f"orbit distance must be positive, got {distance}")
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    target = np.asarray(target, dtype=np.float64).reshape(3)
    outward = np.array([math.sin(az), -math.cos(az), 0.0])  # horizontal, from target to camera
    eye = target + distance * (math.cos(el) * outward + math.sin(el) * np.array([0.0, 0.0, 1.0]))
    # The camera's true up vector: equals +Z's projection for |el| < 90 and stays defined at the poles.
    up = -math.sin(el) * outward + math.cos(el) * np.array([0.0, 0.0, 1.0])
    return Camera.from_fov(width, height, fov_deg, look_at(eye, target, up), axis=axis)


def orbit_cameras(
    n: int,
    elevation_deg: float,
    distance: float,
    width: int,
    height: int,
    fov_deg: float,
    start_azimuth_deg: float = 0.0,
    target: Sequence[float] = (0.0, 0.0, 0.0),
    axis: str = "x",
) -> list[Camera]:
    """`n` orbit cameras at one elevation, azimuths evenly spaced by 360/n from start_azimuth_deg."""
    if n < 1:
        raise ValueError(f"need at least one camera, got n={n}")
    return [
        orbit_camera(start_azimuth_deg + 360.0 * k / n, elevation_deg, distance, width, height, fov_deg,
                     target=target, axis=axis)
        for k in range(n)
    ]


def nearest_cameras(cameras: Mapping[Any, Camera], key: Any, count: int) -> list:
    """The keys of the `count` other cameras whose centres stand nearest to `cameras[key]`'s (ties in
    the mapping's order): the neighbours a view is compared with (floor parallax, photo carving)."""
    centre = cameras[key].center
    return sorted((k for k in cameras if k != key), key=lambda k: float(np.linalg.norm(cameras[k].center - centre)))[:count]
