"""Similarity alignment of point sets and camera-pose error metrics.

Posing (COLMAP, an imported file) gives cameras in an arbitrary world frame and scale, so any
comparison with reference poses first aligns the camera centres with a similarity (Umeyama 1991),
then compares rotations and centres in the reference frame.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from lirm.engine.cameras import Camera

__all__ = ["similarity_align", "apply_similarity", "rotation_angle_deg", "scene_size", "pose_errors"]


def similarity_align(source_points: np.ndarray, target_points: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Least-squares similarity (scale, R, t) with target ≈ scale * R @ source + t (Umeyama).

    R is a proper rotation (det +1): a reflection would fit mirrored data better but is never a
    valid change of world frame for cameras. Needs at least 3 non-collinear points for R to be
    unique; raises ValueError for fewer points, mismatched shapes or a source collapsed to a point.
    """
    src = np.asarray(source_points, dtype=np.float64)
    dst = np.asarray(target_points, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 3 or src.shape != dst.shape:
        raise ValueError(f"need two (N, 3) arrays of corresponding points, got {src.shape} and {dst.shape}")
    if src.shape[0] < 3:
        raise ValueError(f"a similarity needs at least 3 corresponding points, got {src.shape[0]}")
    if not (np.all(np.isfinite(src)) and np.all(np.isfinite(dst))):
        raise ValueError("points must be finite")
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    xs, xd = src - mu_s, dst - mu_d
    var_s = float(np.mean(np.sum(xs * xs, axis=1)))
    if var_s < 1e-300:
        raise ValueError("the source points all coincide: scale and rotation are undefined")
    cov = xd.T @ xs / src.shape[0]
    U, D, Vt = np.linalg.svd(cov)
    S = np.eye(3)
    # Flip the weakest axis when the best orthogonal fit is a reflection (Umeyama's S matrix).
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[2, 2] = -1.0
    R = U @ S @ Vt
    scale = float(np.sum(D * np.diag(S)) / var_s)
    t = mu_d - scale * R @ mu_s
    return scale, R, t


def apply_similarity(scale: float, R: np.ndarray, t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """scale * R @ p + t for points (..., 3)."""
    p = np.asarray(points, dtype=np.float64)
    return scale * p @ np.asarray(R).T + np.asarray(t)


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle in degrees of a 3x3 rotation (0 for the identity)."""
    # Clip: round-off can push the cosine slightly past +-1.
    c = (float(np.trace(R)) - 1.0) * 0.5
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def scene_size(centers: np.ndarray) -> float:
    """Scene size used to express centre errors as fractions: the largest distance between two of
    the given camera centres (the diameter of the camera set). Chosen over a bounding sphere
    because it is exact, simple and independent of any sphere-fitting approximation."""
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 3)
    if c.shape[0] < 2:
        return 0.0
    diff = c[:, None, :] - c[None, :, :]
    return float(np.sqrt(np.max(np.sum(diff * diff, axis=-1))))


def pose_errors(
    estimated: Mapping[str, Camera], reference: Mapping[str, Camera], align: str = "poses"
) -> dict[str, Any]:
    """Compare estimated cameras with reference cameras on the frame ids they share.

    A similarity (scale, R, t) maps the estimated world onto the reference world; an estimated
    camera's c2w rotation becomes R @ R_est there. align="centers" fits it to the camera centres
    alone (Umeyama). align="poses" (default) first fits the centres for the scale, then fits again
    on the centres plus, per camera, the three points one scene size along its x, y and z axes:
    centres of a handheld sweep are often nearly collinear, which leaves the rotation about that
    line free (on 20 fox photos it put 1.1 degrees of error on cameras that agree to 0.15).
    With exact data both recover the same similarity. Per frame:

    - rotation error: the angle (degrees) of R_ref^T @ (R @ R_est), c2w rotations;
    - centre error: |scale * R @ c_est + t - c_ref| divided by the scene size, the largest distance
      between two reference camera centres (`scene_size`), so 0.01 is 1 % of the capture's extent.

    Focal ratio: the median over frames of (fx_est / width_est) / (fx_ref / width_ref), i.e. the
    focal lengths compared at a common image width, so cameras at different resolutions compare.

    Returns a dict with keys frames (sorted shared ids), rotation_deg and center_error (dicts by
    frame id), rotation_deg_median / _max, center_error_median / _max, focal_ratio,
    focal_ratio_per_frame, scene_size, scale, R, t and num_frames. Raises ValueError with fewer
    than 3 shared frames.
    """
    if align not in ("poses", "centers"):
        raise ValueError(f'align must be "poses" or "centers", got {align!r}')
    ids = sorted(set(estimated) & set(reference))
    if len(ids) < 3:
        raise ValueError(
            f"pose comparison needs at least 3 frames present in both sets, got {len(ids)} "
            f"({len(estimated)} estimated, {len(reference)} reference)"
        )
    c_est = np.stack([estimated[i].center for i in ids])
    c_ref = np.stack([reference[i].center for i in ids])
    size = scene_size(c_ref)
    scale, R, t = similarity_align(c_est, c_ref)
    if align == "poses" and size > 0:
        r_est = np.stack([estimated[i].rotation for i in ids])  # (N, 3, 3), columns = camera axes
        r_ref = np.stack([reference[i].rotation for i in ids])
        # (N, 3 axes, 3) axis tips; the estimated ones use the estimated world's units.
        tips_est = c_est[:, None, :] + (size / scale) * np.swapaxes(r_est, 1, 2)
        tips_ref = c_ref[:, None, :] + size * np.swapaxes(r_ref, 1, 2)
        scale, R, t = similarity_align(
            np.concatenate([c_est, tips_est.reshape(-1, 3)]), np.concatenate([c_ref, tips_ref.reshape(-1, 3)])
        )
    aligned = apply_similarity(scale, R, t, c_est)
    rot_err: dict[str, float] = {}
    ctr_err: dict[str, float] = {}
    focal: dict[str, float] = {}
    for k, i in enumerate(ids):
        e, r = estimated[i], reference[i]
        rot_err[i] = rotation_angle_deg(r.rotation.T @ (R @ e.rotation))
        d = float(np.linalg.norm(aligned[k] - c_ref[k]))
        ctr_err[i] = d / size if size > 0 else (0.0 if d == 0 else math.inf)
        focal[i] = (e.fx / e.width) / (r.fx / r.width)
    rots = np.array(list(rot_err.values()))
    ctrs = np.array(list(ctr_err.values()))
    return {
        "frames": ids,
        "num_frames": len(ids),
        "rotation_deg": rot_err,
        "center_error": ctr_err,
        "rotation_deg_median": float(np.median(rots)),
        "rotation_deg_max": float(np.max(rots)),
        "center_error_median": float(np.median(ctrs)),
        "center_error_max": float(np.max(ctrs)),
        "focal_ratio": float(np.median(list(focal.values()))),
        "focal_ratio_per_frame": focal,
        "scene_size": size,
        "scale": scale,
        "R": R,
        "t": t,
    }
