"""Errors of pose estimates against ground truth: interpolation at the estimates' stamps, RMSE, percentiles.

Poses are (x, y, theta) in ``map`` (metres, radians); times in seconds of simulation time. No ROS here.
"""
from __future__ import annotations

import math

import numpy as np

from .geometry import compose2, se2_matrix, wrap_angle


def interpolate(tq: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses (N x 3) at times ``tq``, linear in x, y and the unwrapped heading; NaN outside ``t``'s range."""
    tq = np.asarray(tq, dtype=float)
    t = np.asarray(t, dtype=float)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    out = np.full((len(tq), 3), np.nan)
    if len(t) < 2:
        return out
    inside = (tq >= t[0]) & (tq <= t[-1])
    th = np.unwrap(poses[:, 2])
    out[inside, 0] = np.interp(tq[inside], t, poses[:, 0])
    out[inside, 1] = np.interp(tq[inside], t, poses[:, 1])
    out[inside, 2] = wrap_angle(np.interp(tq[inside], t, th))
    return out


def errors(t_est: np.ndarray, est: np.ndarray, t_gt: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times, position errors m, absolute heading errors rad) of the estimates that fall inside the
    ground truth's time range."""
    est = np.asarray(est, dtype=float).reshape(-1, 3)
    ref = interpolate(t_est, t_gt, gt)
    ok = np.all(np.isfinite(ref), axis=1) & np.all(np.isfinite(est), axis=1)
    d = est[ok] - ref[ok]
    return (np.asarray(t_est)[ok], np.hypot(d[:, 0], d[:, 1]), np.abs(wrap_angle(d[:, 2])))


def stats(values: np.ndarray) -> dict:
    """RMSE, 95th percentile, maximum, median and count of non-negative error values."""
    v = np.asarray(values, dtype=float)
    if len(v) == 0:
        return {"rmse": math.nan, "p95": math.nan, "max": math.nan, "median": math.nan, "n": 0}
    return {"rmse": float(np.sqrt(np.mean(v ** 2))), "p95": float(np.percentile(v, 95)), "max": float(v.max()),
            "median": float(np.median(v)), "n": int(len(v))}


def odometry_in_map(odom: np.ndarray, start_truth: tuple[float, float, float]) -> np.ndarray:
    """Odometry poses (odom frame) expressed in map, the odom frame placed so that the first odometry pose
    coincides with the true pose at that time (odometry alone, started right)."""
    odom = np.asarray(odom, dtype=float).reshape(-1, 3)
    T = se2_matrix(*start_truth) @ np.linalg.inv(se2_matrix(*odom[0]))
    xy = odom[:, :2] @ T[:2, :2].T + T[:2, 3]
    yaw = math.atan2(T[1, 0], T[0, 0])
    return np.column_stack([xy, wrap_angle(odom[:, 2] + yaw)])


def path_length(poses: np.ndarray) -> float:
    p = np.asarray(poses, dtype=float)
    return float(np.sum(np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1])))) if len(p) > 1 else 0.0


def base_from_camera(T_world_cam: np.ndarray, T_cam_base: np.ndarray) -> tuple[float, float, float]:
    """The robot's planar pose implied by a camera pose (used for the paper's camera_pose)."""
    T = T_world_cam @ T_cam_base
    return (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))


__all__ = ["interpolate", "errors", "stats", "odometry_in_map", "path_length", "base_from_camera", "compose2"]
