"""Differential-drive odometry from the encoders' cumulative tick totals, with covariance. No ROS.

Why totals: ``SensorFrame.enc_total`` (``Odo1``/``Odo2``) is the running sum of every per-cycle delta, so
differencing totals against the last frame *used* counts every tick even when datagrams in between were
lost. A lost datagram only makes one integration step longer (the robot's path over the missing cycles is
taken as one constant-curvature arc).

Frames and units: the pose (x, y, theta) is ``base_link`` in the ``odom`` frame (metres, radians, theta
wrapped to (-pi, pi]); v (m/s, forward) and w (rad/s, counter-clockwise) are body velocities averaged over
the last integration step (so they describe the interval (t_prev, t], not the instant t).

Covariance model (per step, wheel travel d_l, d_r in metres, wheels independent):
  pose:  var(d) = slip_var_per_m * |d|, propagated through the arc model's Jacobians to the 3x3
         (x, y, theta) covariance, which therefore grows with the distance travelled (the totals are exact
         floors of the wheel angle, so tick quantisation does not accumulate and is left out);
  twist: var(d) = slip_var_per_m * |d| + tick_m**2 / 6 (the per-step count is the difference of two
         floors, each off by up to one tick), divided by dt**2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import wrap_angle


@dataclass(frozen=True)
class OdometryState:
    """One odometry estimate (``base_link`` in ``odom``) at simulation time ``t`` (s)."""

    t: float
    x: float
    y: float
    theta: float
    v: float  # m/s, mean over the last step
    w: float  # rad/s, mean over the last step
    left_angle: float  # rad, wheel angle from the cumulative total (since the baseline's zero)
    right_angle: float
    left_rate: float  # rad/s, wheel angular speed over the last step
    right_rate: float
    pose_cov: np.ndarray  # 3x3 covariance of (x, y, theta)
    twist_cov: np.ndarray  # 2x2 covariance of (v, w)
    step_ticks: tuple[int, int]  # ticks integrated in the last step (left, right)

    def __iter__(self):  # (x, y, theta, v, w) as in the shared interface
        return iter((self.x, self.y, self.theta, self.v, self.w))


class DiffDriveOdometry:
    """Integrates cumulative encoder totals into a planar pose.

    >>> odo = DiffDriveOdometry(robot)            # robot: robotatfactory.robot.RobotSpec
    >>> x, y, theta, v, w = odo.update(0, 0, 0.0)  # first call: the baseline (no motion)
    >>> x, y, theta, v, w = odo.update(36, 36, 0.04)

    ``update`` returns an :class:`OdometryState` (which also unpacks as ``x, y, theta, v, w``).
    """

    def __init__(self, robot=None, *, wheel_radius: float | None = None, track: float | None = None,
                 ticks_per_rev: int | None = None, slip_var_per_m: float = 1e-4,
                 x: float = 0.0, y: float = 0.0, theta: float = 0.0):
        r = wheel_radius if wheel_radius is not None else robot.wheel_radius
        b = track if track is not None else robot.odometry_track
        n = ticks_per_rev if ticks_per_rev is not None else robot.ticks_per_rev
        if not (r > 0 and b > 0 and n > 0):
            raise ValueError(f"wheel_radius {r}, track {b} and ticks_per_rev {n} must all be > 0")
        if slip_var_per_m < 0:
            raise ValueError(f"slip_var_per_m {slip_var_per_m} must be >= 0")
        self.wheel_radius = float(r)
        self.track = float(b)
        self.ticks_per_rev = int(n)
        self.rad_per_tick = 2 * math.pi / self.ticks_per_rev
        self.m_per_tick = self.rad_per_tick * self.wheel_radius
        self.slip_var_per_m = float(slip_var_per_m)
        self.quant_var = self.m_per_tick ** 2 / 6.0
        self._initial = (float(x), float(y), float(theta))
        self.reset()

    # -- state -------------------------------------------------------------------------------------------
    def reset(self, baseline: tuple[int, int] | None = None, t: float | None = None,
              x: float | None = None, y: float | None = None, theta: float | None = None) -> None:
        """Start again at the initial pose (or the given one).

        ``baseline`` (left, right) is the tick total that corresponds to that pose, and ``t`` its time: pass
        ``(0, 0)`` and ``t = 0`` when the totals count from a known start (a frame with ``Seq`` 0) so that the
        ticks of the very first cycle are counted too; leave them ``None`` to take the next ``update`` as
        the baseline (joining a stream that has been running for a while).
        """
        x0, y0, th0 = self._initial
        self.x = x0 if x is None else float(x)
        self.y = y0 if y is None else float(y)
        self.theta = wrap_angle(th0 if theta is None else float(theta))
        self.cov = np.zeros((3, 3))
        self._last = None if baseline is None else (int(baseline[0]), int(baseline[1]))
        self._t = t
        self._zero = self._last  # totals that correspond to wheel angle 0
        self.v = self.w = 0.0
        self.left_rate = self.right_rate = 0.0
        self._twist_cov = np.diag([self.quant_var, self.quant_var])
        self._step = (0, 0)
        self.distance = 0.0  # m, path length travelled (mean of the wheels' absolute travel)

    @property
    def initialised(self) -> bool:
        return self._last is not None

    def state(self) -> OdometryState:
        zl, zr = self._zero if self._zero is not None else (0, 0)
        ll, lr = self._last if self._last is not None else (zl, zr)
        return OdometryState(
            t=self._t if self._t is not None else 0.0, x=self.x, y=self.y, theta=self.theta, v=self.v, w=self.w,
            left_angle=(ll - zl) * self.rad_per_tick, right_angle=(lr - zr) * self.rad_per_tick,
            left_rate=self.left_rate, right_rate=self.right_rate,
            pose_cov=self.cov.copy(), twist_cov=self._twist_cov.copy(), step_ticks=self._step)

    # -- integration -------------------------------------------------------------------------------------
    def update(self, total_left: int, total_right: int, t: float) -> OdometryState:
        """Integrate the ticks since the last update; ``t`` is the simulation time (s) of these totals."""
        total_left, total_right = int(total_left), int(total_right)
        if self._last is None:
            self._last = self._zero = (total_left, total_right)
            self._t = float(t)
            self._step = (0, 0)
            return self.state()
        dl_ticks = total_left - self._last[0]
        dr_ticks = total_right - self._last[1]
        dt = float(t) - self._t if self._t is not None else 0.0
        self._last = (total_left, total_right)
        self._t = float(t)
        self._step = (dl_ticks, dr_ticks)
        dl = dl_ticks * self.m_per_tick
        dr = dr_ticks * self.m_per_tick
        self._integrate(dl, dr)
        if dt > 0:
            self.v = (dl + dr) / 2 / dt
            self.w = (dr - dl) / self.track / dt
            self.left_rate = dl_ticks * self.rad_per_tick / dt
            self.right_rate = dr_ticks * self.rad_per_tick / dt
            var_l = self.slip_var_per_m * abs(dl) + self.quant_var
            var_r = self.slip_var_per_m * abs(dr) + self.quant_var
            # v = (dl + dr)/(2 dt), w = (dr - dl)/(b dt)
            J = np.array([[0.5, 0.5], [-1 / self.track, 1 / self.track]]) / dt
            self._twist_cov = J @ np.diag([var_l, var_r]) @ J.T
        return self.state()

    def _integrate(self, dl: float, dr: float) -> None:
        ds = (dl + dr) / 2
        dth = (dr - dl) / self.track
        th = self.theta
        # exact constant-curvature arc: x += ds * sinc(dth/2) * cos(th + dth/2)
        half = dth / 2
        k = 1.0 - half * half / 6.0 if abs(half) < 1e-4 else math.sin(half) / half
        c, s = math.cos(th + half), math.sin(th + half)
        self.x += ds * k * c
        self.y += ds * k * s
        self.theta = wrap_angle(th + dth)
        self.distance += (abs(dl) + abs(dr)) / 2
        # covariance propagation (first order, midpoint model): state Jacobian F, input Jacobian G
        F = np.array([[1.0, 0.0, -ds * k * s], [0.0, 1.0, ds * k * c], [0.0, 0.0, 1.0]])
        # d(x,y,th)/d(ds, dth) with the midpoint approximation, then (ds, dth) from (dl, dr)
        Gs = np.array([[c, -ds * s / 2], [s, ds * c / 2], [0.0, 1.0]])
        M = np.array([[0.5, 0.5], [-1 / self.track, 1 / self.track]])
        G = Gs @ M
        # the totals are exact floors, so quantisation does not accumulate in the pose: slip only
        Q = np.diag([self.slip_var_per_m * abs(dl), self.slip_var_per_m * abs(dr)])
        self.cov = F @ self.cov @ F.T + G @ Q @ G.T
