"""The reference route of the localization experiment and a pure-pursuit controller to drive it.

The route is a closed loop of waypoints (map frame, metres) that visits the whole field -- the west side past
the start area, along the incoming warehouse, the north-east, down the east side, along the outgoing
warehouse, up the corridor between the machines and round machine A -- keeping at least 0.13 m between the
robot's centre and any wall, rib or part slot. The controller follows it with a fixed lookahead; it is fed the
ground-truth pose (the experiment measures localization, so control must not depend on it). No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import wrap_angle

#: (x, y) waypoints of one lap, starting at the field's start pose (-0.725, -0.4) heading +y; the lap ends
#: with a small loop back into the start area.
LOOP = (
    (-0.725, -0.40), (-0.70, -0.10), (-0.68, 0.30), (-0.45, 0.36), (-0.10, 0.36), (0.15, 0.37),
    (0.55, 0.38), (0.70, 0.25), (0.69, -0.05), (0.66, -0.30), (0.45, -0.36), (0.10, -0.36),
    (0.00, -0.20), (0.00, 0.05), (-0.05, 0.22), (-0.35, 0.245), (-0.61, 0.17), (-0.62, -0.15),
    (-0.58, -0.36), (-0.66, -0.45), (-0.74, -0.36),
)

def route(laps: int = 2) -> np.ndarray:
    """Waypoints of ``laps`` laps (N x 2)."""
    pts = [LOOP[0]]
    for _ in range(laps):
        pts.extend(LOOP[1:])
    return np.array(pts, dtype=float)


def densify(pts: np.ndarray, step: float = 0.01) -> np.ndarray:
    """The polyline resampled every ``step`` metres."""
    out = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        for i in range(1, n + 1):
            out.append(a + (b - a) * i / n)
    return np.array(out)


def length(pts: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


@dataclass
class PurePursuit:
    """Follows a polyline: steers towards the point ``lookahead`` ahead along the path from the closest point,
    slows down in turns, stops at the end. ``command(pose)`` -> (v, w) in m/s and rad/s."""

    path: np.ndarray  # dense polyline (M x 2)
    speed: float = 0.2
    lookahead: float = 0.10
    max_w: float = 3.0
    goal_tolerance: float = 0.02
    _i: int = 0  # progress index: never goes back (so crossing paths are followed in order)

    def __post_init__(self):
        self.path = densify(np.asarray(self.path, dtype=float))
        self._s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.path, axis=0), axis=1))])

    @property
    def progress(self) -> float:
        """Fraction of the path done (0..1)."""
        return float(self._s[self._i] / self._s[-1]) if self._s[-1] > 0 else 1.0

    _at_goal: bool = False

    @property
    def done(self) -> bool:
        return self._at_goal

    def command(self, pose: tuple[float, float, float]) -> tuple[float, float]:
        x, y, th = pose
        p = np.array([x, y])
        # advance the progress index along a window ahead (no jumping to a later crossing)
        hi = min(len(self.path), self._i + 60)
        d = np.linalg.norm(self.path[self._i:hi] - p, axis=1)
        self._i += int(np.argmin(d))
        goal = self.path[-1]
        if self._i >= len(self.path) - 2 and np.linalg.norm(goal - p) < self.goal_tolerance:
            self._at_goal = True
            return 0.0, 0.0
        target_s = self._s[self._i] + self.lookahead
        j = int(np.searchsorted(self._s, target_s))
        tgt = self.path[min(j, len(self.path) - 1)]
        dx, dy = tgt - p
        c, s = math.cos(th), math.sin(th)
        lx, ly = c * dx + s * dy, -s * dx + c * dy  # target in the robot frame
        L2 = lx * lx + ly * ly
        if L2 < 1e-12:
            return 0.0, 0.0
        alpha = math.atan2(ly, lx)
        if abs(alpha) > math.radians(60):  # far off the heading: turn on the spot first
            return 0.0, math.copysign(min(self.max_w, 2.5 * abs(alpha)), alpha)
        curvature = 2 * ly / L2
        v = self.speed / (1 + 0.15 * abs(curvature))
        remaining = self._s[-1] - self._s[self._i]
        v = min(v, max(0.03, 1.5 * remaining))
        w = max(-self.max_w, min(self.max_w, v * curvature))
        return v, w


def heading_error(a: float, b: float) -> float:
    return abs(wrap_angle(a - b))
