"""Small rigid-body helpers. Units: metres and radians. A 4x4 ``T_a_b`` maps points of frame b into frame a
(``p_a = T_a_b @ p_b``), so ``T_world_cam = T_world_marker @ inv(T_cam_marker)`` is the paper's equation 1.
"""
from __future__ import annotations

import math

import cv2
import numpy as np


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Wrap to (-pi, pi] (the convention of the protocol's ``Theta`` and of ROS's yaw), scalars or arrays."""
    return math.pi - (math.pi - a) % (2 * math.pi)


def inv(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    R, t = T[:3, :3], T[:3, 3]
    out = np.eye(4)
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ t
    return out


def se2_matrix(x: float, y: float, theta: float) -> np.ndarray:
    """4x4 world <- base_link for a robot on the floor at (x, y) with heading theta."""
    c, s = math.cos(theta), math.sin(theta)
    T = np.eye(4)
    T[0, 0], T[0, 1], T[1, 0], T[1, 1] = c, -s, s, c
    T[0, 3], T[1, 3] = x, y
    return T


def matrix_se2(T: np.ndarray) -> tuple[float, float, float]:
    """(x, y, heading) of a 4x4 transform: its translation's x, y and the yaw of its x axis."""
    return float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0])


def rt_matrix(rvec, tvec) -> np.ndarray:
    """4x4 from an OpenCV Rodrigues vector and translation."""
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, dtype=float).reshape(3)
    return T


def matrix_rt(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV (rvec, tvec), each 3x1 float64, of a 4x4 transform."""
    return cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))[0], T[:3, 3].reshape(3, 1).copy()


def tilt_angle(R: np.ndarray) -> float:
    """Angle (rad) between a frame's z axis (third column of R) and the world's z axis."""
    return math.acos(max(-1.0, min(1.0, float(R[2, 2]))))


def rotation_angle(R: np.ndarray) -> float:
    """Angle (rad) of a rotation matrix."""
    return math.acos(max(-1.0, min(1.0, (float(np.trace(R)) - 1.0) / 2.0)))


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (ROS order)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_quat()


def yaw_quaternion(theta: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by theta about z."""
    return (0.0, 0.0, math.sin(theta / 2), math.cos(theta / 2))


def compose2(a: tuple[float, float, float], d: tuple[float, float, float]) -> tuple[float, float, float]:
    """Pose a (x, y, theta) moved by a body-frame increment d (dx, dy, dtheta)."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * d[0] - s * d[1], a[1] + s * d[0] + c * d[1], wrap_angle(a[2] + d[2]))


def between2(a: tuple[float, float, float], b: tuple[float, float, float]) -> tuple[float, float, float]:
    """Body-frame increment from pose a to pose b, i.e. the d with compose2(a, d) == b."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[2] - a[2]))


def se2_log(d: tuple[float, float, float]) -> tuple[float, float, float]:
    """Twist (vx, vy, w) whose exponential over unit time is the body increment d = (dx, dy, dtheta)."""
    dx, dy, th = d
    if abs(th) < 1e-9:
        return (dx, dy, th)
    a = th / 2
    k = a / math.tan(a) if abs(math.tan(a)) > 1e-12 else 0.0  # th/2 * cot(th/2)
    return (k * dx + a * dy, -a * dx + k * dy, th)


def se2_exp(t: tuple[float, float, float]) -> tuple[float, float, float]:
    """Body increment reached by following the constant twist t = (vx, vy, w) for unit time."""
    vx, vy, th = t
    if abs(th) < 1e-9:
        return (vx, vy, th)
    s, c = math.sin(th), math.cos(th)
    a, b = s / th, (1 - c) / th
    return (a * vx - b * vy, b * vx + a * vy, th)


def split_increment(d: tuple[float, float, float], f: float) -> tuple[tuple, tuple]:
    """Split a body increment at fraction f of its (constant-twist) motion: (first, rest)."""
    tw = se2_log(d)
    first = se2_exp(tuple(f * v for v in tw))
    rest = se2_exp(tuple((1 - f) * v for v in tw))
    return first, rest
