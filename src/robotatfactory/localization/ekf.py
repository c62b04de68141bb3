"""An EKF on the robot's (x, y, heading) in ``map``, with time-stamped (possibly late) measurements.

- **Prediction** from wheel odometry: body-frame increments (dx, dy, dtheta) between odometry times, given
  directly (:meth:`Ekf.odometry_increment`), as wheel travel (:meth:`Ekf.odometry_wheels`) or as successive
  odometry poses in the ``odom`` frame (:meth:`Ekf.odometry_pose`). Process noise: each wheel's travel has a
  variance proportional to its length (``wheel_sigma_per_sqrt_m``), plus a little per radian turned (slip)
  and per second (bumps).
- **Carrying a part** (:meth:`Ekf.set_carrying`, time-stamped like a measurement): while the robot holds a
  part on its magnet every radian turned adds ``carry_turn_sigma_per_sqrt_rad`` of heading noise (the part's
  weight and floor friction make the wheels slip as a turn on the spot ends and in arcs; measured with ``raf
  bench turns``, docs/localization.md "Turning with a part"), and a turn on the spot is taken
  ``carry_turn_bias`` larger than the odometry's (the mean of that slip, measured on the real SimTwo). A switch
  stamped before the latest odometry is applied at its own time: the odometry after it is replayed.
- **Updates** from camera pose fixes (:meth:`Ekf.pose_fix`, z = (x, y, heading) of base_link with its
  covariance), from LIDAR scans matched to the map (:meth:`Ekf.pose_fix` with ``source=SCAN``: no
  uncertainty limit, since its covariance is honest along a wall it cannot see along; never initialises or
  re-initialises the filter; counted as ``scan_*``) and from LIDAR beacons (:meth:`Ekf.beacons`,
  range/bearing to known cylinder centres).
- **Late measurements**: the filter keeps the inputs and states of the last ``history_s`` seconds. A
  measurement stamped t is applied at t: the filter goes back to the state before t, splits the odometry
  increment that spans t (constant twist), applies the measurement, and replays the later inputs. A
  measurement newer than the latest odometry waits until odometry reaches its stamp.
- **Uncertain fixes**: a pose fix whose own position sigma exceeds ``max_fix_sigma_xy_m`` (5 cm / 3) is
  not used: the gate alone would let such a fix through although it may be more than 5 cm off.
- **Gating**: squared Mahalanobis distance of the innovation against chi-square gates; gated measurements are
  counted and ignored. The camera stamp's uncertainty (``stamp_sigma_s``) inflates the measurement
  covariance by the motion during that time.
- **Re-initialisation**: uninitialised until the first confident fix; re-initialised from a confident fix
  that is gated after a long time without accepted fixes (``reinit_after_s``) or after
  ``reinit_after_gated`` gated confident fixes in a row (the filter was wrong, e.g. the robot was moved).
  Both count camera fixes only: a scan fix or a beacon, matched from the filter's own pose, leaves them.
- **Final outcomes**: a camera fix can be gated when it arrives and accepted after a later (late-stamped)
  measurement is inserted before it, or the other way round; its outcome is final when it leaves the
  history. :meth:`Ekf.pop_finished_fixes` hands out those final outcomes (the experiment counts accepted
  fixes that were far from the truth).
- **Never NaN**: inputs and results are checked; a bad input or a numerically failed update is counted and
  skipped; covariances are symmetrised and kept within bounds.

No ROS here. Times in seconds (any epoch, monotonic per stream), lengths in metres, angles in radians.
"""
from __future__ import annotations

import bisect
import math
from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from ..settings import setting
from . import reasons
from .geometry import between2, compose2, se2_exp, se2_log, split_increment, wrap_angle

CHI2_3_999 = 16.266  # chi-square, 3 dof, 99.9 %
#: the source of a pose fix from LIDAR scan matching (:mod:`.scanmatch`): matched from the filter's own pose,
#: so it corrects the filter but never initialises or re-initialises it, nor counts as a camera fix
SCAN = "scan"
CHI2_2_999 = 13.816


@dataclass(frozen=True)
class EkfConfig:
    """Settings of the filter (``ekf.*``)."""

    # process noise (fitted to stand-in simulator runs, docs/localization.md)
    wheel_sigma_per_sqrt_m: float = setting(0.005, "m: one wheel's random travel error (1 sigma) after 1 m of its "
                                                   "travel (not a scale error)", lo=0.0)
    turn_sigma_per_sqrt_rad: float = setting(0.005, "rad per sqrt(rad turned): extra heading noise in turns "
                                                    "(slip)", lo=0.0)
    carry_turn_sigma_per_sqrt_rad: float = setting(
        0.03, "rad per sqrt(rad turned) while a part is on the magnet (set_carrying), added to "
              "turn_sigma_per_sqrt_rad: the wheels slip as a turn with a part ends (raf bench turns, stand-in: the "
              "agent's turns end 1.4 +- 2.8 deg off the odometry with a part, p95 7.5, against 0.4 +- 2.8, p95 4.7, "
              "empty; the heading NEES of its carrying turns 1.9 without this, 0.9 with it; "
              "docs/localization.md); 0: carrying changes nothing", lo=0.0)
    carry_turn_bias: float = setting(
        0.017, "fraction: while a part is on the magnet, a turn on the spot (the wheels turning opposite ways) is "
               "taken this much larger than the odometry says: the real SimTwo's carrying turns end 1.70 deg "
               "(sd 0.77) beyond the odometry's, 1.70 % of the degrees turned (the stand-in's 0.7 %; "
               "docs/localization.md \"Turning with a part\"); 0: the odometry's turn", lo=-0.2, hi=0.2)
    xy_sigma_per_sqrt_s: float = setting(0.0005, "m per sqrt(s): random walk of the position while time passes "
                                                 "(bumps, slip)", lo=0.0)
    theta_sigma_per_sqrt_s: float = setting(0.0005, "rad per sqrt(s): the same for the heading", lo=0.0)
    # gates and timing
    gate_pose_chi2: float = setting(CHI2_3_999, "squared Mahalanobis distance above which a pose fix is gated "
                                                "(chi-square, 3 dof, 99.9 %)", lo=0.0, lo_open=True)
    gate_beacon_chi2: float = setting(CHI2_2_999, "likewise for a LIDAR beacon (2 dof, 99.9 %)", lo=0.0,
                                      lo_open=True)
    stamp_sigma_s: float = setting(0.01, "s, uncertainty of a camera frame's stamp (and motion effects while "
                                         "turning)", lo=0.0)
    history_s: float = setting(3.0, "s: late measurements up to this old are applied at their own time", lo=0.0,
                               lo_open=True)
    max_pending: int = setting(20, "measurements at most waiting for odometry to reach their stamp", lo=1)
    # re-initialisation
    reinit_after_s: float = setting(5.0, "s: a confident fix gated after this long without an accepted one "
                                         "re-initialises the filter", lo=0.0)
    reinit_after_gated: int = setting(6, "... or after this many confident fixes gated in a row", lo=1)
    confident_sigma_xy_m: float = setting(0.02, "m, the position sigma of a fix that may (re-)initialise the "
                                                "filter", lo=0.0)
    confident_sigma_theta_deg: float = setting(3.0, "deg, and its heading sigma", lo=0.0, hi=180.0)
    max_fix_sigma_xy_m: float = setting(0.0165, "m: a camera fix less certain than this (the larger position "
                                                "sigma of its covariance) is not used: such a fix could be more "
                                                "than 5 cm off and still pass the gate; 5 cm / 3 (0: no limit)",
                                        lo=0.0)
    # covariance bounds (after a long outage the covariance stops growing)
    max_sigma_xy_m: float = setting(3.0, "m, the position sigma at most (a long outage stops growing there)",
                                    lo=0.0, lo_open=True)
    max_sigma_theta_rad: float = setting(math.pi, "rad, the heading sigma at most", lo=0.0, lo_open=True)
    min_variance: float = setting(1e-12, "the covariance's eigenvalues at least (m^2, rad^2)", lo=0.0,
                                  lo_open=True)
    # set in code, not a setting: the robot file's odometry track (the node sets it)
    track_m: float = 0.135  # m, wheel separation (for the wheel-travel noise)


@dataclass(frozen=True)
class FilterState:
    x: np.ndarray | None  # (x, y, theta) or None before initialisation
    P: np.ndarray | None
    t: float
    last_fix_t: float = -math.inf  # time of the last accepted (or initialising) absolute update
    gated_run: int = 0  # consecutive gated confident fixes
    carrying: bool = False  # a part on the magnet (Ekf.set_carrying): the carrying process noise applies


@dataclass(frozen=True)
class _Odom:
    t0: float
    t1: float
    inc: tuple[float, float, float]


@dataclass(frozen=True)
class _Carry:
    t: float
    on: bool


@dataclass(frozen=True)
class _Pose:
    t: float
    z: np.ndarray
    R: np.ndarray
    source: str = "camera"


@dataclass(frozen=True)
class _Beacons:
    t: float
    obs: tuple  # ((range, bearing, var_r, var_b), ...)
    beacons: np.ndarray  # K x 2 world centres
    laser_xy: tuple[float, float]
    laser_yaw: float


@dataclass(frozen=True)
class FinishedFix:
    """The final outcome of one absolute pose measurement (it left the filter's history or the filter was
    re-initialised): stamp t (s), z = (x, y, heading), its covariance R, accepted (incl. re-initialising)."""

    t: float
    z: tuple[float, float, float]
    R: np.ndarray
    source: str
    accepted: bool
    reason: str | None


@dataclass
class UpdateResult:
    """What happened to one measurement (for diagnostics). ``accepted`` False: see ``reason``."""

    accepted: bool
    reason: str | None = None
    mahalanobis2: float = float("nan")
    n_used: int = 0


class Ekf:
    """See the module docstring. ``counts`` counts outcomes by reason."""

    def __init__(self, cfg: EkfConfig | None = None):
        self.cfg = cfg or EkfConfig()
        self._log: list[tuple[float, object]] = []  # (time, record), time-ordered
        self._states: list[FilterState] = []  # state after each record
        self._results: list[UpdateResult | None] = []  # outcome of each record (None: odometry)
        self._finished: list[FinishedFix] = []
        self.max_finished = 10000  # finished fixes kept until popped
        self._base = FilterState(None, None, -math.inf)  # state before the first record
        self._pending: list[_Pose | _Beacons | _Carry] = []
        self._carry_last: tuple[float, bool] | None = None  # the switch given last (t, on)
        self._last_odom_pose: tuple[float, tuple] | None = None
        self.counts: Counter = Counter()
        self.last_result: UpdateResult | None = None
        self._replaying = False

    # ------------------------------------------------------------------ state access
    @property
    def state(self) -> FilterState:
        return self._states[-1] if self._states else self._base

    @property
    def initialised(self) -> bool:
        return self.state.x is not None

    @property
    def t(self) -> float:
        return self.state.t

    def pose(self) -> tuple[float, float, float] | None:
        s = self.state
        return None if s.x is None else (float(s.x[0]), float(s.x[1]), float(s.x[2]))

    def covariance(self) -> np.ndarray | None:
        s = self.state
        return None if s.P is None else s.P.copy()

    def initialise(self, t: float, pose: tuple[float, float, float], cov: np.ndarray) -> None:
        """Start (or restart) from a known pose at time t (e.g. the start pose with a loose covariance)."""
        z, R = np.array(pose, dtype=float), np.asarray(cov, dtype=float)
        if not (np.all(np.isfinite(z)) and np.all(np.isfinite(R))):
            self.counts[reasons.BAD_INPUT] += 1
            return
        carrying = self.state.carrying
        self._finish(len(self._log))
        self._log.clear()
        self._states.clear()
        self._results.clear()
        self._pending = [m for m in self._pending if isinstance(m, _Carry)]  # a later switch stays due
        self._base = FilterState(self._wrap(z), self._bound(R), t, t, 0, carrying)

    @property
    def carrying(self) -> bool:
        """Whether the process noise of carrying a part applies at the filter's time."""
        return self.state.carrying

    # ------------------------------------------------------------------ inputs
    def odometry_increment(self, t: float, inc: tuple[float, float, float]) -> bool:
        """The robot moved by the body-frame increment ``inc`` = (dx, dy, dtheta) from the previous odometry
        time to ``t``. The first call (or one after a gap in time) only sets the clock when ``inc`` is None."""
        if not (math.isfinite(t) and all(math.isfinite(v) for v in inc)):
            self.counts[reasons.BAD_INPUT] += 1
            return False
        t0 = self.state.t
        if t0 == -math.inf:
            self._base = replace(self._base, t=t)
            return True
        if t < t0:
            self.counts[reasons.TOO_OLD] += 1
            return False
        # measurements waiting for this odometry: split the increment at their stamps
        due = sorted((m for m in self._pending if m.t <= t), key=lambda m: m.t)
        self._pending = [m for m in self._pending if m.t > t]
        cur_t0, rest = t0, tuple(inc)
        for m in due:
            if t > cur_t0 and m.t > cur_t0:
                f = (m.t - cur_t0) / (t - cur_t0)
                first, rest = split_increment(rest, f)
                self._append(m.t, _Odom(cur_t0, m.t, first))
                cur_t0 = m.t
            r = self._append(max(m.t, cur_t0), m)
            if r is not None:  # (a carrying switch has no outcome)
                self.last_result = r
        self._append(t, _Odom(cur_t0, t, rest))
        self._prune()
        return True

    def odometry_wheels(self, t: float, d_left: float, d_right: float) -> bool:
        """Wheel travel (m) since the previous odometry time: an arc."""
        if not (math.isfinite(d_left) and math.isfinite(d_right)):
            self.counts[reasons.BAD_INPUT] += 1
            return False
        ds, dth = (d_left + d_right) / 2, (d_right - d_left) / self.cfg.track_m
        if abs(dth) < 1e-9:
            return self.odometry_increment(t, (ds, 0.0, dth))
        r = ds / dth
        return self.odometry_increment(t, (r * math.sin(dth), r * (1 - math.cos(dth)), dth))

    def odometry_pose(self, t: float, pose: tuple[float, float, float]) -> bool:
        """Successive odometry poses (odom frame); the filter uses the increments between them."""
        if not (math.isfinite(t) and all(math.isfinite(v) for v in pose)):
            self.counts[reasons.BAD_INPUT] += 1
            return False
        prev = self._last_odom_pose
        self._last_odom_pose = (t, tuple(pose))
        if prev is None or self.state.t == -math.inf:
            if self.state.t == -math.inf:
                self._base = replace(self._base, t=t)
            return True
        return self.odometry_increment(t, between2(prev[1], pose))

    def set_carrying(self, t: float, on: bool) -> bool:
        """From time t on the robot carries a part on its magnet (``on``) or not: the odometry after t gets the
        carrying process noise (``carry_turn_sigma_per_sqrt_rad``). Stamped like a measurement: a switch older
        than the latest odometry is applied at its own time (the odometry increment spanning t is split and the
        later inputs replayed), one newer waits until odometry reaches it (it is never dropped to make room),
        one older than the history applies from the history's start. Each call is a switch, kept in order of its
        stamp whatever order the calls come in: call it when the command changes (the node does). Returns
        whether it was taken (not: a bad stamp, or the very switch given last)."""
        if not math.isfinite(t):
            self.counts[reasons.BAD_INPUT] += 1
            return False
        on = bool(on)
        if (t, on) == self._carry_last:
            return False
        self._carry_last = (t, on)
        self._insert(_Carry(max(t, self._base.t), on))
        return True

    def pose_fix(self, t: float, z: tuple[float, float, float], R: np.ndarray, source: str = "camera") -> UpdateResult:
        """An absolute pose of base_link in map at time t (e.g. a camera fix) with covariance R (3x3)."""
        z = np.asarray(z, dtype=float).reshape(3)
        R = np.asarray(R, dtype=float).reshape(3, 3)
        if not (math.isfinite(t) and np.all(np.isfinite(z)) and np.all(np.isfinite(R))) or np.any(np.diag(R) <= 0):
            self.counts[reasons.BAD_INPUT] += 1
            return UpdateResult(False, reasons.BAD_INPUT)
        return self._insert(_Pose(t, z, 0.5 * (R + R.T), source))

    def beacons(self, t: float, observations: list[tuple[float, float, float, float]], beacon_xy: np.ndarray,
                laser_xy: tuple[float, float] = (0.0, 0.0), laser_yaw: float = 0.0) -> UpdateResult:
        """Beacon observations (range m, bearing rad in the laser frame, variances) at time t; each is associated
        with the nearest known beacon (``beacon_xy``, K x 2 in map) by Mahalanobis distance and gated."""
        obs = tuple(tuple(float(v) for v in o) for o in observations
                    if len(o) == 4 and all(math.isfinite(float(v)) for v in o) and o[0] > 0 and o[2] > 0 and o[3] > 0)
        if not math.isfinite(t) or not obs:
            if observations:
                self.counts[reasons.BAD_INPUT] += 1
                return UpdateResult(False, reasons.BAD_INPUT)
            return UpdateResult(False, None)
        return self._insert(_Beacons(t, obs, np.asarray(beacon_xy, dtype=float).reshape(-1, 2),
                                     tuple(laser_xy), float(laser_yaw)))

    # ------------------------------------------------------------------ timeline
    def _insert(self, m) -> UpdateResult:
        t_now = self.state.t
        if m.t > t_now or t_now == -math.inf:
            waiting = [i for i, p in enumerate(self._pending) if not isinstance(p, _Carry)]
            if len(waiting) >= self.cfg.max_pending and not isinstance(m, _Carry):
                self._pending.pop(waiting[0])  # the oldest measurement makes room (a carrying switch never)
                self.counts[reasons.TOO_OLD] += 1
            self._pending.append(m)
            return UpdateResult(False, "pending")
        if m.t < self._base.t:
            self.counts[reasons.TOO_OLD] += 1
            return UpdateResult(False, reasons.TOO_OLD)
        # position in the log: after every record with time <= m.t
        times = [r[0] for r in self._log]
        k = bisect.bisect_right(times, m.t)
        if k == len(self._log):
            return self._append(m.t, m)
        rec_t, rec = self._log[k]
        tail = self._log[k:]
        del self._log[k:]
        del self._states[k:]
        del self._results[k:]
        result = None
        if isinstance(rec, _Odom) and rec.t0 < m.t < rec.t1:
            f = (m.t - rec.t0) / (rec.t1 - rec.t0)
            first, rest = split_increment(rec.inc, f)
            self._append(m.t, _Odom(rec.t0, m.t, first))
            result = self._append(m.t, m)
            tail[0] = (rec_t, _Odom(m.t, rec.t1, rest))
        else:
            result = self._append(m.t, m)
        self._replaying = True
        try:
            for rt, r in tail:
                self._append(rt, r)
        finally:
            self._replaying = False
        return result

    def _append(self, t: float, rec) -> UpdateResult | None:
        s = self.state
        if isinstance(rec, _Odom):
            ns = self._predict(s, rec)
            res = None
        elif isinstance(rec, _Carry):
            ns, res = replace(s, carrying=rec.on), None
        elif isinstance(rec, _Pose):
            ns, res = self._update_pose(s, rec)
        else:
            ns, res = self._update_beacons(s, rec)
        if res is not None and not self._replaying:
            key = res.reason or "accepted"
            self.counts[f"scan_{key}" if isinstance(rec, _Pose) and rec.source == SCAN else key] += 1
        self._log.append((t, rec))
        self._states.append(ns)
        self._results.append(res)
        return res

    def _prune(self) -> None:
        horizon = self.state.t - self.cfg.history_s
        n = 0
        while n < len(self._log) - 1 and self._log[n][0] < horizon:
            n += 1
        if n:
            self._base = self._states[n - 1]
            self._finish(n)
            del self._log[:n]
            del self._states[:n]
            del self._results[:n]

    def _finish(self, n: int) -> None:
        """Record the final outcome of the pose measurements among the first ``n`` records."""
        for (t, rec), res in zip(self._log[:n], self._results[:n]):
            if isinstance(rec, _Pose) and res is not None:
                self._finished.append(FinishedFix(t, tuple(float(v) for v in rec.z), rec.R, rec.source,
                                                  bool(res.accepted), res.reason))
        if len(self._finished) > self.max_finished:
            del self._finished[:len(self._finished) - self.max_finished]

    def pop_finished_fixes(self) -> list[FinishedFix]:
        """Pose measurements whose outcome became final since the last call (oldest first)."""
        out, self._finished = self._finished, []
        return out

    # ------------------------------------------------------------------ maths
    def _bound(self, P: np.ndarray) -> np.ndarray:
        P = 0.5 * (P + P.T)
        c = self.cfg
        lim = np.array([c.max_sigma_xy_m ** 2, c.max_sigma_xy_m ** 2, c.max_sigma_theta_rad ** 2])
        d = np.diag(P).copy()
        if np.any(d > lim):
            s = np.sqrt(np.minimum(d, lim) / np.maximum(d, 1e-300))
            P = P * np.outer(s, s)
        w, V = np.linalg.eigh(P)
        if w.min() < c.min_variance:
            P = (V * np.maximum(w, c.min_variance)) @ V.T
            P = 0.5 * (P + P.T)
        return P

    @staticmethod
    def _wrap(x: np.ndarray) -> np.ndarray:
        x = np.array(x, dtype=float)
        x[2] = wrap_angle(float(x[2]))
        return x

    def _process_noise(self, inc: tuple[float, float, float], dt: float, carrying: bool = False) -> np.ndarray:
        """Covariance of the body increment (dx, dy, dtheta) from wheel-travel noise, turning (more with a part
        on the magnet: ``carrying``) and time."""
        c = self.cfg
        vx, vy, w = se2_log(inc)
        b = c.track_m
        dl, dr = vx - w * b / 2, vx + w * b / 2
        k2 = c.wheel_sigma_per_sqrt_m ** 2
        var_l, var_r = k2 * abs(dl), k2 * abs(dr)
        S = np.array([[(var_l + var_r) / 4, (var_r - var_l) / (2 * b)],
                      [(var_r - var_l) / (2 * b), (var_l + var_r) / b ** 2]])
        turn_var = c.turn_sigma_per_sqrt_rad ** 2 + (c.carry_turn_sigma_per_sqrt_rad ** 2 if carrying else 0.0)
        S[1, 1] += turn_var * abs(w)
        h = w / 2
        G = np.array([[math.cos(h), -vx / 2 * math.sin(h)], [math.sin(h), vx / 2 * math.cos(h)], [0.0, 1.0]])
        Q = G @ S @ G.T
        dt = max(dt, 0.0)
        Q += np.diag([c.xy_sigma_per_sqrt_s ** 2 * dt, c.xy_sigma_per_sqrt_s ** 2 * dt,
                      c.theta_sigma_per_sqrt_s ** 2 * dt])
        return Q

    def _carried(self, inc: tuple[float, float, float]) -> tuple[float, float, float]:
        """The body increment ``inc`` as the robot with a part makes it: where the wheels turn opposite ways (a
        turn on the spot), the turn ``carry_turn_bias`` larger at the same speed along."""
        k = self.cfg.carry_turn_bias
        if k == 0.0:
            return inc
        vx, vy, w = se2_log(inc)
        if abs(w) * self.cfg.track_m / 2 <= abs(vx):  # both wheels the same way: driving, not turning on the spot
            return inc
        return se2_exp((vx, vy, w * (1.0 + k)))

    def _predict(self, s: FilterState, rec: _Odom) -> FilterState:
        if s.x is None:
            return replace(s, t=rec.t1)
        th = float(s.x[2])
        c, sn = math.cos(th), math.sin(th)
        inc = self._carried(rec.inc) if s.carrying else rec.inc
        dx, dy, dth = inc
        x = np.array(compose2(tuple(s.x), inc))
        F = np.array([[1, 0, -sn * dx - c * dy], [0, 1, c * dx - sn * dy], [0, 0, 1.0]])
        Wr = np.array([[c, -sn, 0], [sn, c, 0], [0, 0, 1.0]])
        Q = Wr @ self._process_noise(rec.inc, rec.t1 - rec.t0, s.carrying) @ Wr.T
        P = F @ s.P @ F.T + Q
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            self.counts[reasons.NUMERICAL] += 0 if self._replaying else 1
            return replace(s, t=rec.t1)
        return replace(s, x=self._wrap(x), P=self._bound(P), t=rec.t1)

    def _velocity_at(self, t: float, carrying: bool = False) -> np.ndarray:
        """World-frame (vx, vy, w) from the odometry record spanning t (zero if none), as :meth:`_predict` takes
        it: the carried increment while ``carrying``."""
        for rt, r in reversed(self._log):
            if isinstance(r, _Odom) and r.t0 <= t <= r.t1 + 1e-9 and r.t1 > r.t0:
                vx, vy, w = se2_log(self._carried(r.inc) if carrying else r.inc)
                dt = r.t1 - r.t0
                th = float(self.state.x[2]) if self.state.x is not None else 0.0
                c, s = math.cos(th), math.sin(th)
                return np.array([(c * vx - s * vy) / dt, (s * vx + c * vy) / dt, w / dt])
            if rt < t - 1.0:
                break
        return np.zeros(3)

    def _confident(self, R: np.ndarray) -> bool:
        c = self.cfg
        return math.sqrt(max(R[0, 0], R[1, 1])) <= c.confident_sigma_xy_m and \
            math.sqrt(R[2, 2]) <= math.radians(c.confident_sigma_theta_deg)

    def _update_pose(self, s: FilterState, m: _Pose) -> tuple[FilterState, UpdateResult]:
        c = self.cfg
        camera = m.source != SCAN
        if camera and c.max_fix_sigma_xy_m > 0 and \
                math.sqrt(max(np.linalg.eigvalsh(m.R[:2, :2]))) > c.max_fix_sigma_xy_m:
            return s, UpdateResult(False, reasons.UNCERTAIN)
        if s.x is None:
            if not camera or not self._confident(m.R):
                return s, UpdateResult(False, "waiting_for_confident_fix")
            return (FilterState(self._wrap(m.z), self._bound(m.R), s.t, s.t, 0, s.carrying),
                    UpdateResult(True, reasons.REINITIALISED))
        v = self._velocity_at(m.t, s.carrying)
        R = m.R + np.outer(v, v) * c.stamp_sigma_s ** 2
        nu = m.z - s.x
        nu[2] = wrap_angle(float(nu[2]))
        S = s.P + R
        try:
            L = np.linalg.cholesky(S)
            y = np.linalg.solve(L, nu)
            d2 = float(y @ y)
        except np.linalg.LinAlgError:
            return s, UpdateResult(False, reasons.NUMERICAL)
        if not math.isfinite(d2):
            return s, UpdateResult(False, reasons.NUMERICAL)
        if d2 > c.gate_pose_chi2:
            if not camera:  # a scan fix is matched from the filter's own pose: it never re-initialises it
                return s, UpdateResult(False, reasons.GATED, d2)
            confident = self._confident(m.R)
            outage = (s.t - s.last_fix_t) > c.reinit_after_s
            run = s.gated_run + 1 if confident else s.gated_run
            if confident and (outage or run >= c.reinit_after_gated):
                return FilterState(self._wrap(m.z), self._bound(m.R), s.t, s.t, 0, s.carrying), \
                    UpdateResult(True, reasons.REINITIALISED, d2, 1)
            return replace(s, gated_run=run), UpdateResult(False, reasons.GATED, d2)
        K = np.linalg.solve(S, s.P).T  # P S^-1 (S, P symmetric)
        x = s.x + K @ nu
        IKH = np.eye(3) - K
        P = IKH @ s.P @ IKH.T + K @ R @ K.T  # Joseph form
        if not (np.all(np.isfinite(x)) and np.all(np.isfinite(P))):
            return s, UpdateResult(False, reasons.NUMERICAL, d2)
        if not camera:  # the camera's outage clock and gated run are the camera's: a scan fix leaves them
            return replace(s, x=self._wrap(x), P=self._bound(P)), UpdateResult(True, None, d2, 1)
        return FilterState(self._wrap(x), self._bound(P), s.t, s.t, 0, s.carrying), UpdateResult(True, None, d2, 1)

    def _update_beacons(self, s: FilterState, m: _Beacons) -> tuple[FilterState, UpdateResult]:
        if s.x is None:
            return s, UpdateResult(False, "waiting_for_confident_fix")
        c = self.cfg
        x, P = s.x.copy(), s.P.copy()
        used, gated, d2s = 0, 0, []
        for (rng, brg, vr, vb) in m.obs:
            best = None
            for bxy in m.beacons:
                zhat, H = beacon_model(x, bxy, m.laser_xy, m.laser_yaw)
                if zhat is None:
                    continue
                R = np.diag([vr, vb])
                nu = np.array([rng - zhat[0], wrap_angle(brg - zhat[1])])
                S = H @ P @ H.T + R
                try:
                    d2 = float(nu @ np.linalg.solve(S, nu))
                except np.linalg.LinAlgError:
                    continue
                if math.isfinite(d2) and (best is None or d2 < best[0]):
                    best = (d2, nu, H, S, R)
            if best is None or best[0] > c.gate_beacon_chi2:
                gated += 1
                continue
            d2, nu, H, S, R = best
            K = P @ H.T @ np.linalg.inv(S)
            xn = x + K @ nu
            IKH = np.eye(3) - K @ H
            Pn = IKH @ P @ IKH.T + K @ R @ K.T
            if np.all(np.isfinite(xn)) and np.all(np.isfinite(Pn)):
                x, P = self._wrap(xn), self._bound(Pn)
                used += 1
                d2s.append(d2)
        if not used:
            return s, UpdateResult(False, reasons.GATED if gated else reasons.NUMERICAL)
        # like a scan fix, beacons are associated from the filter's own pose and leave the camera's outage clock
        # and gated run alone: accepted while the pose is wrong along what they do not see, they would stop the
        # camera's re-initialisation for good
        return replace(s, x=x, P=P), UpdateResult(True, None, float(np.mean(d2s)), used)


def beacon_model(x: np.ndarray, beacon_xy, laser_xy=(0.0, 0.0), laser_yaw: float = 0.0):
    """Predicted (range, bearing) of a beacon centre from the laser at pose x, and its 2x3 Jacobian."""
    c, s = math.cos(x[2]), math.sin(x[2])
    ox, oy = laser_xy
    lx, ly = x[0] + c * ox - s * oy, x[1] + s * ox + c * oy
    dlx, dly = -s * ox - c * oy, c * ox - s * oy  # d(lx, ly)/dtheta
    dx, dy = beacon_xy[0] - lx, beacon_xy[1] - ly
    r2 = dx * dx + dy * dy
    if r2 < 1e-8:
        return None, None
    r = math.sqrt(r2)
    zhat = np.array([r, wrap_angle(math.atan2(dy, dx) - x[2] - laser_yaw)])
    H = np.array([[-dx / r, -dy / r, -(dx * dlx + dy * dly) / r],
                  [dy / r2, -dx / r2, (-dx * dly + dy * dlx) / r2 - 1.0]])
    return zhat, H
