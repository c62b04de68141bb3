"""Test frames for the bench and calibration: random robot poses on the field and their synthetic camera
images (:mod:`.synth`, no simulator needed). The stand-in simulator's images of the same poses are the
bench's (``bench/localization.py``): localization does not depend on the simulator.
"""
from __future__ import annotations

import math
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
