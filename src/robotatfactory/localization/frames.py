"""Test frames for the bench and calibration: random robot poses on the field and their camera images.

Images come from the synthetic renderer (:mod:`.synth`, no simulator needed) or from the stand-in simulator's
MuJoCo camera (``robotatfactory.sim``), which is what the ROS node sees in the experiment.
"""
from __future__ import annotations

import math
import os
from typing import Iterator

import numpy as np

from ..field.model import Field
from ..robot import RobotSpec


def clearance(field: Field, x: float, y: float) -> float:
    """Distance (m) from (x, y) to the nearest wall footprint (negative inside one)."""
    best = math.inf
    for b in field.boxes:
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        dx, dy = x - b.center[0], y - b.center[1]
        lx, ly = abs(c * dx + s * dy) - b.size[0] / 2, abs(-s * dx + c * dy) - b.size[1] / 2
        d = math.hypot(max(lx, 0.0), max(ly, 0.0)) if (lx > 0 or ly > 0) else max(lx, ly)
        best = min(best, d)
    return best


def random_poses(field: Field, n: int, seed: int = 0, min_clearance: float = 0.08,
                 edge_margin: float = 0.08) -> list[tuple[float, float, float]]:
    """``n`` robot poses uniformly on the floor, at least ``min_clearance`` from walls and ``edge_margin``
    inside the floor's edge, uniform heading."""
    rng = np.random.default_rng(seed)
    a = field.floor
    out = []
    while len(out) < n:
        x = rng.uniform(a.x[0] + edge_margin, a.x[1] - edge_margin)
        y = rng.uniform(a.y[0] + edge_margin, a.y[1] - edge_margin)
        if clearance(field, x, y) < min_clearance:
            continue
        out.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    return out


def synthetic_frames(field: Field, robot: RobotSpec, poses, seed: int = 0, blur_sigma: float = 0.6,
                     noise_sigma: float = 2.0) -> Iterator[tuple[tuple[float, float, float], np.ndarray]]:
    from .synth import SceneRenderer

    r = SceneRenderer(field, robot.camera)
    rng = np.random.default_rng(seed)
    for p in poses:
        yield p, r.render(p, blur_sigma=blur_sigma, noise_sigma=noise_sigma, rng=rng)


def simulator_frames(field: Field, robot: RobotSpec, poses, seed: int = 0) -> Iterator[tuple[tuple, np.ndarray]]:
    """Camera images rendered by the stand-in simulator with the robot placed at each pose."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    try:
        from ..sim import SimConfig, Simulator
    except Exception as e:  # the simulator is another part of the project
        from ..errors import ConfigError

        raise ConfigError(f"the stand-in simulator is not available ({type(e).__name__}: {e})") from None
    sim = Simulator(field, robot, SimConfig(seed=seed))
    try:
        for p in poses:
            sim.set_pose(*p)
            yield p, np.ascontiguousarray(sim.render_camera())
    finally:
        close = getattr(sim, "close", None)
        if close:
            close()


def frames(source: str, field: Field, robot: RobotSpec, poses, seed: int = 0):
    if source == "synth":
        return synthetic_frames(field, robot, poses, seed)
    if source == "sim":
        return simulator_frames(field, robot, poses, seed)
    from ..errors import ConfigError

    raise ConfigError(f"frame source must be synth or sim, not {source!r}")
