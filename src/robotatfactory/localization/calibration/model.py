"""The camera model of the calibration: its parameter vector (:data:`PARAMS`), one frame's data
(:class:`FrameData`) and the projection of world points into the image (OpenCV's pinhole and
plumb-bob distortion, the robot's mount conventions of :class:`~robotatfactory.robot.CameraSpec`)."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from ...robot import CameraSpec
from ..detect import Detection

#: The camera parameters of the model, in the order of the parameter vector (units in docs above).
PARAMS = ("fx", "fy", "cx", "cy", "x", "y", "z", "pitch_down_deg", "roll_deg", "k1", "k2", "p1", "p2", "k3",
          "corner_bias_px")
DEFAULT_FREE = ("fx", "fy", "cx", "cy", "z", "pitch_down_deg", "roll_deg")
DISTORTION = ("k1", "k2", "p1", "p2", "k3")
UNITS = {"fx": "px", "fy": "px", "cx": "px", "cy": "px", "x": "m", "y": "m", "z": "m", "pitch_down_deg": "deg",
         "roll_deg": "deg", "k1": "", "k2": "", "p1": "", "p2": "", "k3": "", "corner_bias_px": "px"}


@dataclass
class FrameData:
    """One frame's detections of known markers (pixels, as detected, i.e. distorted) and its odometry."""

    stamp: float
    detections: list[Detection]
    odom: tuple[float, float, float] | None = None  # base_link in odom (m, m, rad) at the frame's stamp


# -------------------------------------------------------------------------------------------- camera model


def camera_vector(cam: CameraSpec) -> np.ndarray:
    """The :data:`PARAMS` vector of a camera."""
    return np.array([cam.fx, cam.fy, cam.cx, cam.cy, *cam.xyz, cam.pitch_down_deg, cam.roll_deg, *cam.distortion,
                     0.0], dtype=float)


def camera_from_vector(base: CameraSpec, v: Sequence[float]) -> CameraSpec:
    """``base`` (image size, timing) with the parameters of a :data:`PARAMS` vector."""
    v = [float(a) for a in v]
    return replace(base, fx=v[0], fy=v[1], cx=v[2], cy=v[3], xyz=(v[4], v[5], v[6]), pitch_down_deg=v[7],
                   roll_deg=v[8], distortion=tuple(v[9:14]))


def _rot_base_optical(pitch_deg: float, roll_deg: float) -> np.ndarray:
    p, r = math.radians(pitch_deg), math.radians(roll_deg)
    c, s, cr, sr = math.cos(p), math.sin(p), math.cos(r), math.sin(r)
    Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    L = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)
    return Ry @ Rx @ L


def distort(xn: np.ndarray, yn: np.ndarray, d: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's plumb-bob model on normalised coordinates."""
    k1, k2, p1, p2, k3 = d
    if not (k1 or k2 or p1 or p2 or k3):
        return xn, yn
    r2 = xn * xn + yn * yn
    rad = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * rad + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * rad + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


def project_corners(v: np.ndarray, poses: np.ndarray, P: np.ndarray, fi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (Mx2) and depths (M) of world points ``P`` (Mx3) seen from the robot poses ``poses[fi]`` (x, y,
    heading) by the camera of parameter vector ``v`` (:data:`PARAMS`)."""
    R_bo = _rot_base_optical(v[7], v[8])
    R_cb = R_bo.T
    t_cb = -R_cb @ v[4:7]
    x, y, th = poses[fi, 0], poses[fi, 1], poses[fi, 2]
    c, s = np.cos(th), np.sin(th)
    qx, qy = P[:, 0] - x, P[:, 1] - y
    b = np.stack([c * qx + s * qy, -s * qx + c * qy, P[:, 2]], axis=1)
    pc = b @ R_cb.T + t_cb
    Z = pc[:, 2]
    iz = 1.0 / np.where(np.abs(Z) < 1e-6, 1e-6, Z)
    xd, yd = distort(pc[:, 0] * iz, pc[:, 1] * iz, v[9:14])
    return np.stack([v[0] * xd + v[2], v[1] * yd + v[3]], axis=1), Z


def predict_corners(v: np.ndarray, poses: np.ndarray, P: np.ndarray, fi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_corners` plus the detector's corner bias ``v[14]`` (pixels, outward along each corner's
    direction from the marker's centre). ``P`` holds whole markers: 4 consecutive corners each."""
    uv, Z = project_corners(v, poses, P, fi)
    b = float(v[14]) if len(v) > 14 else 0.0
    if b:
        q = uv.reshape(-1, 4, 2)
        d = q - q.mean(axis=1, keepdims=True)
        d /= np.maximum(np.linalg.norm(d, axis=2, keepdims=True), 1e-9)
        uv = (q + b * d).reshape(-1, 2)
    return uv, Z
