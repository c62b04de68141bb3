"""A path follower on the pose estimate: turn in place, then drive along each segment with a speed profile.

Input each control cycle: the robot's pose estimate (x, y, theta) in the field frame (m, rad), e.g. the
EKF's ``pose``. Output: body speeds (v m/s forward, w rad/s counter-clockwise) for ``cmd_vel``.

Behaviour (the stack that won RobotAtFactory 4.0 in 2022/2023 did the same, on an omnidirectional robot):

* **No translation while the heading error exceeds** ``heading_tolerance`` (0.2 rad): the robot turns
  in place towards the segment first. Driving, the heading is steered back onto the line through a
  point ``lookahead`` m ahead (cross-track correction).
* **Speed profile** with acceleration limits: v never changes by more than ``a_max * dt`` per cycle (SimTwo's
  speed controller has no ramp: a step in the command slips the tyres), braking as ``sqrt(v_c^2 + 2 a d)``
  to a stop at every waypoint where the path turns by more than the heading tolerance and at the end,
  and to ``v_max (1 - turn / tolerance)`` (at least ``v_final``) at gentler corners.
* **Slow in the last** ``slow_distance`` (0.05 m) before the end: at most ``v_final``.
* At the end, an optional final heading is turned to in place. ``reverse=True`` drives the path backwards
  (the robot's back first), for backing out of a slot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .footprint import wrap


@dataclass(frozen=True)
class DriveLimits:
    """Speed and acceleration limits of the base (m/s, m/s^2, rad/s, rad/s^2) and the profile's settings."""

    v_max: float = 0.4
    w_max: float = 3.0
    a_max: float = 0.8  # measured: 0.5 -> 0.8 cut round 1 from 79.6 to 70.9 s, all 30 runs at the maximum
    alpha_max: float = 6.0
    v_final: float = 0.08
    slow_distance: float = 0.05  # docking approaches slowly anyway (0.2 m: +15 s in round 1)
    heading_tolerance: float = 0.2
    lookahead: float = 0.12
    k_heading: float = 8.0  # 1/s: w = k_heading * heading error, within the limits (4: slow tails of turns)
    position_tolerance: float = 0.005  # m: the end is reached within this distance along the path
    heading_goal_tolerance: float = 0.015  # rad: the final heading is reached within this

    @classmethod
    def from_robot(cls, robot, fraction: float = 0.45, a_max: float = 0.8, **kw) -> DriveLimits:
        """Limits from the robot file: the wheels' no-load top speed (Vmax / Ke rad/s, the motor model) times
        ``fraction`` caps v (and v + |w| track / 2 at each wheel); ``a_max`` (m/s^2) at the rim bounds the
        angular acceleration as well (alpha = a_max / (track / 2))."""
        m = robot.motor
        top = float(m["Vmax"]) / float(m["Ke"]) / float(m.get("gear", 1.0)) * robot.wheel_radius  # m/s
        v_max = min(kw.pop("v_max", 0.4), fraction * top)
        half = robot.track / 2
        return cls(v_max=v_max, w_max=kw.pop("w_max", min(3.0, fraction * top / half)), a_max=a_max,
                   alpha_max=kw.pop("alpha_max", a_max / half), **kw)


@dataclass(frozen=True)
class FollowerOutput:
    """One cycle's command and what the follower saw (m, rad)."""

    v: float
    w: float
    done: bool
    phase: str  # "turn", "drive", "final_turn", "done"
    segment: int
    cross_track: float  # signed distance to the current segment's line, left positive
    heading_error: float  # to the segment (or the final heading), rad
    remaining: float  # path length left (m)


class PathFollower:
    """Follows one path at a time: :meth:`start`, then :meth:`step` every ``dt`` seconds."""

    def __init__(self, limits: DriveLimits, dt: float):
        self.limits = limits
        self.dt = float(dt)
        self.points = np.zeros((0, 2))
        self.final_heading: float | None = None
        self.reverse = False
        self.k = 0
        self.v = 0.0
        self.w = 0.0
        self.phase = "done"
        self._stop_at: list[bool] = []
        self._seg_len = np.zeros(0)

    def start(self, points, final_heading: float | None = None, reverse: bool = False) -> None:
        """A new path ((x, y) waypoints, m; the first is where the robot is). The commanded speeds carry
        over (no jump when a path replaces another while moving)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        keep = [0] + [i for i in range(1, len(pts)) if np.hypot(*(pts[i] - pts[i - 1])) > 1e-6]
        self.points = pts[keep]
        self.final_heading = final_heading
        self.reverse = reverse
        self.k = 0
        self._seg_len = np.hypot(*np.diff(self.points, axis=0).T) if len(self.points) > 1 else np.zeros(0)
        n = len(self.points) - 1
        tol = self.limits.heading_tolerance
        self._stop_at = []
        self._corner_v = []  # the speed allowed at the end of segment i (m/s)
        for i in range(n):  # stop at the end of segment i?
            if i == n - 1:
                self._stop_at.append(True)
                self._corner_v.append(0.0)
            else:
                turn = abs(wrap(self._heading(i + 1) - self._heading(i)))
                self._stop_at.append(turn > tol)
                self._corner_v.append(0.0 if turn > tol else
                                      max(self.limits.v_final, self.limits.v_max * (1.0 - turn / tol)))
        self.phase = "turn" if n > 0 else ("final_turn" if final_heading is not None else "done")

    def _heading(self, i: int) -> float:
        a, b = self.points[i], self.points[i + 1]
        return math.atan2(b[1] - a[1], b[0] - a[0])

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def stop(self) -> None:
        """Abandon the path (the next step brakes to a stop within the limits)."""
        self.points = self.points[:1]
        self._seg_len = np.zeros(0)
        self.final_heading = None
        self.phase = "done"

    # ------------------------------------------------------------------------------------------ step
    def step(self, pose) -> FollowerOutput:
        """One control cycle from the pose estimate (x, y, theta); returns the command to send."""
        L = self.limits
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        if self.reverse:
            th = wrap(th + math.pi)  # drive the back first: the follower works on the flipped heading
        cross = herr = 0.0
        remaining = 0.0
        v_t = w_t = 0.0
        n = len(self.points) - 1
        if self.phase in ("turn", "drive") and n > 0:
            # advance past segments whose end is reached (projection beyond the end)
            while True:
                a, b = self.points[self.k], self.points[self.k + 1]
                d = b - a
                u = d / self._seg_len[self.k]
                along = float((x - a[0]) * u[0] + (y - a[1]) * u[1])
                to_end = self._seg_len[self.k] - along
                if to_end <= L.position_tolerance and self.k < n - 1 and (not self._stop_at[self.k] or self.v == 0.0):
                    self.k += 1
                    if self._stop_at[self.k - 1]:
                        self.phase = "turn"
                    continue
                break
            cross = float(-(x - a[0]) * u[1] + (y - a[1]) * u[0])
            seg_th = math.atan2(u[1], u[0])
            remaining = max(to_end, 0.0) + float(np.sum(self._seg_len[self.k + 1:]))
            if to_end <= L.position_tolerance and self.k == n - 1:
                self.phase = "final_turn" if self.final_heading is not None else "done"
            else:
                # the speed allowed now: braking to each coming corner's speed, up to the next stop
                j = self.k
                d_c = max(to_end, 0.0) - self.v * self.dt
                v_allowed = L.v_max
                while True:
                    v_allowed = min(v_allowed, math.sqrt(self._corner_v[j] ** 2 + 2 * L.a_max * max(d_c, 0.0)))
                    if self._stop_at[j]:
                        break
                    j += 1
                    d_c += self._seg_len[j]
                aim = seg_th + math.atan2(-cross, L.lookahead)
                herr = wrap(aim - th)
                if self.phase == "turn" and abs(herr) <= L.heading_tolerance / 2:
                    self.phase = "drive"
                if abs(herr) > L.heading_tolerance:
                    self.phase = "turn"
                # turning in place only once stopped: no translation while the heading error is large
                w_t = self._turn_rate(herr) if (self.phase == "drive" or self.v == 0.0) else 0.0
                if self.phase == "drive" and not (self._stop_at[self.k] and to_end <= L.position_tolerance):
                    v_t = v_allowed
                    # at most v_final in the last slow_distance: braking for it starts before
                    gap = max(remaining - L.slow_distance - self.v * self.dt, 0.0)
                    v_t = min(v_t, math.sqrt(L.v_final ** 2 + 2 * L.a_max * gap))
                    v_t = min(v_t, max(remaining / self.dt, 0.0))  # never past the end in one cycle
                    v_t *= max(0.0, math.cos(herr))
        if self.phase == "final_turn":
            target = self.final_heading if not self.reverse else wrap(self.final_heading + math.pi)
            herr = wrap(target - th)
            if abs(herr) <= L.heading_goal_tolerance and abs(self.w) <= L.alpha_max * self.dt:
                self.phase = "done"
            else:
                w_t = self._turn_rate(herr)
        # acceleration limits
        dv, dw = L.a_max * self.dt, L.alpha_max * self.dt
        self.v += max(-dv, min(dv, v_t - self.v))
        self.w += max(-dw, min(dw, w_t - self.w))
        if self.phase == "done" and abs(self.v) < 1e-9 and abs(self.w) < 1e-9:
            self.v = self.w = 0.0
        v_out = -self.v if self.reverse else self.v
        return FollowerOutput(v_out, self.w, self.phase == "done" and self.v == 0.0 and self.w == 0.0, self.phase,
                              self.k, cross, herr, remaining)

    def _turn_rate(self, err: float) -> float:
        L = self.limits
        # braking-distance limited so an in-place turn stops on the heading
        cap = min(L.w_max, math.sqrt(2 * L.alpha_max * abs(err)), L.k_heading * abs(err) + 0.05)
        return math.copysign(cap, err) if abs(err) > 1e-4 else 0.0
