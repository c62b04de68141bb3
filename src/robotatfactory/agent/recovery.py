"""Recovery helpers of the round's behaviour: how uncertain the pose is, turning towards markers to
re-localize, and noticing that the robot is stuck (a blocked path).

* :func:`uncertainty_of` reads the pose's reported uncertainty in any of the forms a caller has: None, a
  position standard deviation (m), a pair (position m, heading rad), or a covariance of (x, y, theta)
  (3 x 3) or of a ROS ``PoseWithCovariance`` (6 x 6 or its 36 numbers: x, y, z, roll, pitch, yaw).
* :class:`Relocalizer`: standing still, turn slowly in place to face the nearest markers the camera can see
  (floor markers 0.12-0.8 m away, or wall markers whose face looks at the robot), one after the other,
  dwelling on each, while the localization's uncertainty shrinks. Every heading it turns through is
  checked with the robot's exact outline first (``can_turn``); a turn that would touch something is not
  made.
* :class:`StuckDetector`: the robot commanded to move but moved less than ``min_motion`` over
  ``window`` seconds is stuck (something blocks the path that the map does not have).

Frames and units: the field frame, metres, radians, seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .follower import spin_rate
from .footprint import wrap


def uncertainty_of(u) -> tuple[float, float] | None:
    """(position standard deviation m, heading standard deviation rad) from ``u`` (see the module
    docstring); None when ``u`` is None. The position figure is sqrt(var x + var y)."""
    if u is None:
        return None
    if isinstance(u, (int, float)):
        return float(u), 0.0
    a = np.asarray(u, dtype=float)
    if a.shape == (2,):
        return float(a[0]), float(a[1])
    if a.size == 36:
        a = a.reshape(6, 6)
        return math.sqrt(max(a[0, 0] + a[1, 1], 0.0)), math.sqrt(max(a[5, 5], 0.0))
    if a.shape == (3, 3):
        return math.sqrt(max(a[0, 0] + a[1, 1], 0.0)), math.sqrt(max(a[2, 2], 0.0))
    raise ValueError(f"uncertainty {u!r}: expected a float, (pos, heading), a 3x3 or a 6x6 covariance")


@dataclass(frozen=True)
class RelocalizeSettings:
    w: float = 0.6  # rad/s, slow: the camera must see the markers sharp
    dwell: float = 1.0  # s facing one marker before turning to the next
    min_range: float = 0.12  # m: closer floor markers are under the camera's view
    max_range: float = 0.8  # m
    step: float = 0.1  # rad between the headings checked for a turn


class Relocalizer:
    """Turns in place towards markers, one after the other (see the module docstring)."""

    def __init__(self, field, can_turn: Callable[[tuple[float, float, float]], bool],
                 settings: RelocalizeSettings = RelocalizeSettings()):
        self.settings = settings
        self.can_turn = can_turn
        self.markers = [(float(m.pose[0, 3]), float(m.pose[1, 3]), str(m.kind), np.asarray(m.normal, float))
                        for m in field.markers]
        self.targets: list[float] = []
        self.k = 0
        self._dwell = 0.0
        self.blocked = 0

    def start(self, pose) -> None:
        """Choose the markers to look at from ``pose``: the nearest visible ones first (their headings)."""
        x, y, _ = pose
        s = self.settings
        cand = []
        for mx, my, kind, n in self.markers:
            d = math.hypot(mx - x, my - y)
            if not s.min_range <= d <= s.max_range:
                continue
            if kind != "floor" and n[0] * (x - mx) + n[1] * (y - my) <= 0.2 * d:
                continue  # a wall marker whose face looks away
            cand.append((d, math.atan2(my - y, mx - x)))
        cand.sort()
        self.targets = []
        for _, h in cand:  # distinct headings only (markers side by side are seen together)
            if all(abs(wrap(h - g)) > 0.35 for g in self.targets):
                self.targets.append(h)
        self.k = 0
        self._dwell = 0.0
        self.blocked = 0

    def step(self, pose, dt: float) -> float:
        """The turn rate (rad/s) for this cycle, the robot standing."""
        if not self.targets:
            return 0.0
        th = float(pose[2])
        for _ in range(len(self.targets)):
            target = self.targets[self.k % len(self.targets)]
            err = wrap(target - th)
            if abs(err) <= 0.05:
                self._dwell += dt
                if self._dwell >= self.settings.dwell:
                    self.k += 1
                    self._dwell = 0.0
                    continue
                return 0.0
            nxt = th + math.copysign(min(self.settings.step, abs(err)), err)
            if self.can_turn((pose[0], pose[1], nxt)):
                return spin_rate(err, self.settings.w, 2.0, 0.05)
            self.blocked += 1  # this marker cannot be faced from here: the next one
            self.k += 1
            self._dwell = 0.0
        return 0.0


@dataclass
class StuckDetector:
    """Stuck: over ``window`` s the robot was commanded at least ``min_command`` m/s (or its turn rate at
    least ``min_turn`` rad/s) on average, but moved less than ``min_motion`` m and turned less than
    ``min_rotation`` rad. Motion is measured between the means of the window's first and last thirds, so a
    noisy pose estimate (a few mm of white noise) does not look like motion."""

    window: float = 1.5
    min_command: float = 0.04
    min_turn: float = 0.4
    min_motion: float = 0.01
    min_rotation: float = 0.05

    def __post_init__(self):
        self.reset()

    def reset(self) -> None:
        self._t0: float | None = None
        self._poses: list = []
        self._cmd = 0.0
        self._turn = 0.0

    def update(self, t: float, pose, v_cmd: float, w_cmd: float) -> bool:
        """One cycle; True when stuck (then the window starts again)."""
        if self._t0 is None:
            self._t0 = t
        self._poses.append((float(pose[0]), float(pose[1]), math.cos(pose[2]), math.sin(pose[2])))
        self._cmd += abs(v_cmd)
        self._turn += abs(w_cmd)
        if t - self._t0 < self.window or len(self._poses) < 6:
            return False
        a = np.asarray(self._poses)
        k = len(a) // 3
        first, last = a[:k].mean(axis=0), a[-k:].mean(axis=0)
        moved = math.hypot(last[0] - first[0], last[1] - first[1])
        turned = abs(wrap(math.atan2(last[3], last[2]) - math.atan2(first[3], first[2])))
        n = len(a)
        busy = self._cmd / n >= self.min_command or self._turn / n >= self.min_turn
        stuck = busy and moved < self.min_motion and turned < self.min_rotation
        self.reset()
        return stuck
