"""Synthetic calibration data for tests and experiments: a perturbed robot camera, exact projections of the
markers it would see, and a fitted camera's errors against the true one."""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from ...field.model import Field
from ...robot import CameraSpec, RobotSpec
from ..detect import Detection
from ..geometry import between2, compose2
from .model import FrameData, camera_vector, project_corners


def perturbed_robot(robot: RobotSpec, fx_pct: float = 3.0, fy_pct: float | None = None, cx_px: float = 4.0,
                    cy_px: float = -3.0, pitch_deg: float = 1.0, roll_deg: float = 0.0, height_m: float = 0.0,
                    forward_m: float = 0.0, distortion: Sequence[float] | None = None) -> RobotSpec:
    """``robot`` with its camera changed: focal lengths by a percentage (``fy_pct`` defaults to ``fx_pct``),
    principal point by pixels, pitch down and roll by degrees, mount height and forward offset by metres.
    The issue's test case is the default (fx, fy +3 %, cx +4 px, cy -3 px, pitch +1 degree)."""
    c = robot.camera
    fy_pct = fx_pct if fy_pct is None else fy_pct
    cam = replace(c, fx=c.fx * (1 + fx_pct / 100), fy=c.fy * (1 + fy_pct / 100), cx=c.cx + cx_px, cy=c.cy + cy_px,
                  pitch_down_deg=c.pitch_down_deg + pitch_deg, roll_deg=c.roll_deg + roll_deg,
                  xyz=(c.xyz[0] + forward_m, c.xyz[1], c.xyz[2] + height_m),
                  distortion=tuple(distortion) if distortion is not None else c.distortion)
    return replace(robot, camera=cam)


def compare(fitted: CameraSpec, truth: CameraSpec) -> dict:
    """Errors of a fitted camera against the true one, flat keys with units."""
    return {
        "fx_error_pct": 100 * (fitted.fx - truth.fx) / truth.fx,
        "fy_error_pct": 100 * (fitted.fy - truth.fy) / truth.fy,
        "cx_error_px": fitted.cx - truth.cx,
        "cy_error_px": fitted.cy - truth.cy,
        "pitch_error_deg": fitted.pitch_down_deg - truth.pitch_down_deg,
        "roll_error_deg": fitted.roll_deg - truth.roll_deg,
        "height_error_mm": 1000 * (fitted.xyz[2] - truth.xyz[2]),
        "forward_error_mm": 1000 * (fitted.xyz[0] - truth.xyz[0]),
    }


def synthetic_frames(fld: Field, camera: CameraSpec, poses: Sequence[tuple[float, float, float]],
                     noise_px: float = 0.0, seed: int = 0, odom_noise: float = 0.0,
                     outliers: int = 0) -> list[FrameData]:
    """Exact projections (with the camera's distortion) of every marker fully inside the image, plus Gaussian
    noise; odometry = the true poses (with ``odom_noise`` relative noise on each step); ``outliers`` random
    detections get a corner moved by 5-20 px. For tests: no rendering."""
    from ..synth import camera_world_pose, visible_markers

    rng = np.random.default_rng(seed)
    pinhole = replace(camera, distortion=(0.0,) * 5)
    v = camera_vector(camera)
    out = []
    odo = None
    prev = None
    for k, p in enumerate(poses):
        T = camera_world_pose(camera, p)
        vis = visible_markers(fld, pinhole, T, margin_px=3.0, min_side_px=6.0)
        dets = []
        for vm in vis:
            m = fld.marker(vm.id)
            uv, _ = project_corners(v, np.array([p], dtype=float), m.corners, np.zeros(4, dtype=int))
            if np.any(uv < 0) or np.any(uv[:, 0] > camera.width - 1) or np.any(uv[:, 1] > camera.height - 1):
                continue
            uv = uv + rng.normal(0, noise_px, uv.shape) if noise_px > 0 else uv
            dets.append(Detection(vm.id, uv))
        if prev is None:
            odo = tuple(p)
        else:
            d = np.array(between2(prev, p))
            if odom_noise > 0:
                d = d * (1 + rng.normal(0, odom_noise, 3))
            odo = compose2(odo, tuple(d))
        prev = tuple(p)
        out.append(FrameData(float(k), dets, odo))
    for _ in range(outliers):
        cand = [f for f in out if f.detections]
        f = cand[int(rng.integers(len(cand)))]
        i = int(rng.integers(len(f.detections)))
        d = f.detections[i]
        c = d.corners.copy()
        c[int(rng.integers(4))] += rng.uniform(5, 20, 2) * rng.choice([-1, 1], 2)
        f.detections[i] = Detection(d.id, c)
    return out
