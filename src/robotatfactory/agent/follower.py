"""A path follower on the pose estimate: turns while it drives on a smooth path (lines and arcs), stops and
turns in place only where the path has a corner it could not round.

Input each control cycle: the robot's pose estimate (x, y, theta) in the field frame (m, rad), e.g. the
EKF's ``pose``. Output: body speeds (v m/s forward, w rad/s counter-clockwise) for ``cmd_vel``.

The path is a :class:`~.smooth.SmoothPath` (the planner's, whose arcs are checked against the robot's
exact outline) or a bare polyline (rounded only where an arc stays within 3 mm of the corner).

* **Steering:** feed-forward from the path's curvature (w = v kappa, kappa read a little ahead for the
  acceleration limit) plus feedback on the heading towards a point ``lookahead`` m ahead on the path's
  tangent (cross-track correction): w = v kappa + k_heading * heading error.
* **No translation while the heading error exceeds** ``heading_tolerance`` (0.2 rad): at the start of each
  piece (after a stop) the robot turns in place first (the stack that won RobotAtFactory 4.0 did the same).
* **Speed profile** with acceleration limits: v never changes by more than ``a_max * dt`` per cycle
  (SimTwo's speed controller has no ramp: a step slips the tyres); on arcs at most the speed where the
  outer wheel reaches ``v_wheel``, w reaches ``w_max`` or the lateral acceleration ``a_lat``; braking as
  ``sqrt(v_c^2 + 2 a d)`` before every slower stretch, every stop and the end; at most ``v_final`` in the
  last ``slow_distance`` unless the path ends at ``end_speed`` > 0 (the docking approach follows on).
* At the end an optional final heading is turned to in place. ``reverse=True`` drives the path backwards
  (the robot's back first), for backing out of a slot.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .footprint import wrap
from .smooth import Piece, SmoothPath, smooth_path


#: m/s: the least speed the follower drives at on a piece before its end (it still ends within one cycle: at
#: most the distance left); below it the approach to a stop tends to zero speed without reaching the end
CREEP_SPEED = 0.02


def spin_rate(err: float, w_max: float, gain: float, offset: float = 0.0, alpha_max: float | None = None,
              brake: float = 1.0) -> float:
    """The turn rate (rad/s) of a turn on the spot towards a heading ``err`` rad away (signed as ``err``):
    ``gain`` x |err| + ``offset`` (the offset keeps the last hundredths of a radian moving), at most ``w_max``
    and, with ``alpha_max``, no faster than braking at ``brake`` x ``alpha_max`` stops within |err|
    (sqrt(2 brake alpha_max |err|)). The follower's turns on the spot, the re-localization's and the search for a
    lost part's (:mod:`.floor`) use it, each with its own figures, ramped by :func:`ramp`."""
    a = abs(err)
    cap = min(w_max, gain * a + offset)
    if alpha_max is not None:
        cap = min(cap, math.sqrt(2 * brake * alpha_max * a))
    return math.copysign(cap, err)


def ramp(now: float, want: float, step: float) -> float:
    """``now`` moved towards ``want`` by at most ``step`` (a speed within its acceleration limit times a cycle)."""
    return now + max(-step, min(step, want - now))


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
    k_heading: float = 8.0  # 1/s: turning on the spot, w = k_heading * heading error, within the limits
    # 1/s: driving, w = v kappa + k_drive * heading error (8 oscillates with a pose one cycle late: the place
    # approach then jams the part between ribs; measured rounds 1-3, docs/agent.md)
    k_drive: float = 4.0
    position_tolerance: float = 0.005  # m: the end is reached within this distance along the path
    heading_goal_tolerance: float = 0.015  # rad: the final heading is reached within this
    v_wheel: float = 0.46  # m/s at either wheel's rim (from_robot: the same fraction of the top speed)
    a_lat: float = 1.0  # m/s^2 lateral acceleration on arcs
    half_track: float = 0.0675  # m, half the wheel track (the wheel-speed limit on arcs)
    spin_curvature: float = 6.0  # 1/m: with no_spin, |w| <= this x v + spin_slack (rad/s)
    spin_slack: float = 0.15
    max_off_path: float = 0.1  # m: farther from the path the follower stops and says so (off_path)
    ff_lead: float = 2.0  # control cycles the curvature feed-forward reads ahead (the wheels' response delay)
    # a turn on the spot of more than long_spin rad (0: off) runs at most w_long_spin rad/s throughout: carrying on
    # SimTwo's magnet the part slides along the face the farther and the faster the robot turns, and a turn back
    # the other way after a long fast one pivots it off (docs/agent.md, "The carry envelope")
    long_spin: float = 0.0
    w_long_spin: float = 0.0
    # rad (0: off): a turn on the spot ends standing within this of the heading before the robot drives off
    # (off: it drives off still turning once within heading_tolerance / 2). Carrying, driving off a turn while
    # the heading feedback turns back slips the wheels under the part where the encoders cannot see it
    # (docs/localization.md, "Turning with a part")
    spin_settle: float = 0.0
    # m (0: every turn): spin_settle only for a turn with at most this much path left after it (a short
    # approach, where no camera fix comes in time to correct the heading; on a longer leg the overlap saves time)
    spin_settle_within: float = 0.0

    @classmethod
    def from_robot(cls, robot, fraction: float = 0.45, a_max: float = 0.8, **kw) -> DriveLimits:
        """Limits from the robot file: the wheels' no-load top speed (Vmax / Ke rad/s, the motor model) times
        ``fraction`` caps v (and v + |w| track / 2 at each wheel); ``a_max`` (m/s^2) at the rim bounds the
        angular acceleration as well (alpha = a_max / (track / 2))."""
        m = robot.motor
        top = float(m["Vmax"]) / float(m["Ke"]) / float(m.get("gear", 1.0)) * robot.wheel_radius  # m/s
        # a v_max given is taken as given (it was capped at the fraction silently: drive.v_max 0.55 ran at 0.46);
        # the wheels' limit then allows it on a straight
        v_max = kw.pop("v_max", min(0.4, fraction * top))
        half = robot.track / 2
        return cls(v_max=v_max, w_max=kw.pop("w_max", min(3.0, fraction * top / half)), a_max=a_max,
                   alpha_max=kw.pop("alpha_max", a_max / half), v_wheel=kw.pop("v_wheel", max(fraction * top, v_max)),
                   half_track=half, **kw)


@dataclass(frozen=True)
class FollowerOutput:
    """One cycle's command and what the follower saw (m, rad)."""

    v: float
    w: float
    done: bool
    phase: str  # "turn", "drive", "final_turn", "done"
    segment: int  # the piece being driven (pieces are separated by stops)
    cross_track: float  # signed distance to the path, left positive
    heading_error: float  # to the aim point (or the final heading), rad
    remaining: float  # path length left (m)
    off_path: float = 0.0  # m from the path when more than max_off_path (the robot stopped following), else 0


class PathFollower:
    """Follows one path at a time: :meth:`start`, then :meth:`step` every ``dt`` seconds."""

    def __init__(self, limits: DriveLimits, dt: float):
        self.limits = limits
        self.dt = float(dt)
        self.path = SmoothPath(())
        self.final_heading: float | None = None
        self.reverse = False
        self.end_speed = 0.0
        self.no_spin = False
        self.k = 0
        self.v = 0.0
        self.w = 0.0
        self.phase = "done"
        self._s = 0.0
        self._i = 0
        self._dist = 0.0
        self._prof: list[np.ndarray] = []
        self._spin_cap = math.inf  # rad/s for the turn on the spot under way (long_spin)
        self._spinning = False

    @property
    def points(self) -> np.ndarray:
        return self.path.points

    def start(self, path, final_heading: float | None = None, reverse: bool = False,
              end_speed: float = 0.0, no_spin: bool = False, speeds: tuple[float, float] | None = None) -> None:
        """A new path: a :class:`SmoothPath` or (x, y) waypoints (m; the first is where the robot is).
        ``end_speed`` (m/s) > 0: the path ends without stopping (no final heading then), ``done`` is
        reported when its end is passed. ``no_spin``: never turn on the spot (carrying a part on SimTwo's
        magnet): the turn rate stays within ``spin_curvature`` times the speed, plus the feedback's
        ``spin_slack``; the path's pieces must start along the robot's heading (:mod:`.hybrid`). The
        commanded speeds carry over (no jump when a path replaces another while moving): this follower's own,
        or ``speeds``, the (v, w) last commanded (v > 0 forwards), where the commands came from elsewhere since
        its last step (the caller braked or turned by itself: the follower would set off from the speed it was
        stopped at)."""
        if not isinstance(path, SmoothPath):
            path = smooth_path(path)
        self.path = path
        self.final_heading = final_heading
        self.reverse = reverse
        self.end_speed = float(end_speed)
        self.no_spin = bool(no_spin)
        if speeds is not None:
            self.v, self.w = (-float(speeds[0]) if reverse else float(speeds[0])), float(speeds[1])
        self.k = 0
        self._s, self._i = 0.0, 0
        self._spinning = False
        self._prof = [self._profile(p, last=(j == len(path.pieces) - 1)) for j, p in enumerate(path.pieces)]
        total = path.length
        if total <= 1e-9:
            self.phase = "final_turn" if final_heading is not None else "done"
        else:
            self.phase = "drive" if no_spin else "turn"
            while self.path.pieces[self.k].length <= 1e-9 and self.k < len(self.path.pieces) - 1:
                self.k += 1

    def _profile(self, p: Piece, last: bool) -> np.ndarray:
        """The speed allowed at each sample of a piece (m/s): curvature limits, then braking backwards from
        its end (a stop, or ``end_speed`` at the path's end), and the slow end."""
        L = self.limits
        k = np.abs(p.kappa)
        with np.errstate(divide="ignore"):
            v = np.minimum.reduce([np.full(len(k), L.v_max), L.v_wheel / (1.0 + k * L.half_track),
                                   np.where(k > 1e-9, L.w_max / np.maximum(k, 1e-9), np.inf),
                                   np.where(k > 1e-9, np.sqrt(L.a_lat / np.maximum(k, 1e-9)), np.inf)])
        # the turn rate needs time to build up at the entry of an arc (alpha_max): at most half the arc goes by
        run = np.zeros(len(k))  # length of the stretch of constant curvature each sample lies on
        i = 0
        while i < len(k):
            j = i
            while j + 1 < len(k) and abs(p.kappa[j + 1] - p.kappa[i]) < 1e-6:
                j += 1
            run[i:j + 1] = p.s[j] - p.s[i]
            i = j + 1
        v = np.minimum(v, np.where(k > 1e-9, np.sqrt(0.5 * L.alpha_max * np.maximum(run, 0.01) / np.maximum(k, 1e-9)),
                                   np.inf))
        end = self.end_speed if last else 0.0
        if last and end <= 0.0:
            v = np.minimum(v, np.where(p.s >= p.length - L.slow_distance, L.v_final, np.inf))
        v[-1] = min(v[-1], end)
        for i in range(len(v) - 2, -1, -1):
            v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * L.a_max * (p.s[i + 1] - p.s[i])))
        return v

    def estimate(self, path: SmoothPath, heading: float, end_speed: float = 0.0) -> float:
        """Seconds to drive ``path`` from standing at ``heading`` (rad), roughly and in a millisecond (no step run,
        unlike a kinematic run of :meth:`step`): each piece a turn on the spot onto its first heading (at
        ``w_max``, or ``w_long_spin`` past ``long_spin``; ``alpha_max``), then its speed profile driven up from
        rest at ``a_max``. For ranking paths; the follower's feedback and ramps are left out. Replaces the path
        being followed (:meth:`start`)."""
        L = self.limits
        self.start(path, end_speed=end_speed)
        t, h = 0.0, float(heading)
        for p, prof in zip(path.pieces, self._prof):
            err = abs(wrap(float(p.psi[0]) - h))
            w = L.w_long_spin if L.long_spin > 0 and L.w_long_spin > 0 and err > L.long_spin else L.w_max
            t += err / w + w / L.alpha_max if err >= w * w / L.alpha_max else 2.0 * math.sqrt(err / L.alpha_max)
            ds = np.diff(p.s)
            v = prof.copy()
            v[0] = 0.0
            for i in range(1, len(v)):
                v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2.0 * L.a_max * ds[i - 1]))
            t += float(np.sum(ds / np.maximum(0.5 * (v[1:] + v[:-1]), CREEP_SPEED)))
            h = float(p.psi[-1])
        self.stop()
        return t

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def suspend(self) -> dict:
        """The path under way and how far along it the robot is, for :meth:`resume` after a stop; then
        :meth:`stop`."""
        held = dict(vars(self))
        self.stop()
        return held

    def resume(self, held: dict, speeds: tuple[float, float]) -> None:
        """Go on along the path :meth:`suspend` returned from where the robot stands now (it stopped on it): from
        the speeds last commanded, ``speeds`` (v, w), as in :meth:`start`."""
        self.__dict__.update(held)
        self.v, self.w = (-float(speeds[0]) if self.reverse else float(speeds[0])), float(speeds[1])

    def stop(self) -> None:
        """Abandon the path (the next step brakes to a stop within the limits)."""
        self.path = SmoothPath(())
        self._prof = []
        self.final_heading = None
        self.end_speed = 0.0
        self.phase = "done"

    # ------------------------------------------------------------------------------------------ step
    def _project(self, p: Piece, x: float, y: float) -> tuple[float, float]:
        """Arc length of the point of ``p`` nearest (x, y), searched forward from the last one (m), and the
        signed cross-track distance (left positive)."""
        xy = p.xy
        n = len(xy)
        if n == 1:
            self._dist = float(math.hypot(x - xy[0, 0], y - xy[0, 1]))
            return 0.0, 0.0
        i0 = max(self._i - 2, 0)
        i1 = min(n - 1, self._i + 40)
        a = xy[i0:i1]
        b = xy[i0 + 1:i1 + 1]
        d = b - a
        dd = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
        u = np.clip(((x - a[:, 0]) * d[:, 0] + (y - a[:, 1]) * d[:, 1]) / dd, 0.0, 1.0)
        q = a + u[:, None] * d
        dist = np.hypot(q[:, 0] - x, q[:, 1] - y)
        j = int(np.argmin(dist))
        self._i = i0 + j
        s = float(p.s[self._i] + u[j] * (p.s[self._i + 1] - p.s[self._i]))
        if j == len(dist) - 1 and u[j] >= 1.0:  # beyond the end: extend the last tangent
            t = np.array([math.cos(p.psi[-1]), math.sin(p.psi[-1])])
            s = p.length + float((x - xy[-1, 0]) * t[0] + (y - xy[-1, 1]) * t[1])
        _, _, psi, _ = p.at(min(s, p.length))
        qx, qy, _, _ = p.at(min(max(s, 0.0), p.length))
        cross = -(x - qx) * math.sin(psi) + (y - qy) * math.cos(psi)
        self._dist = float(np.min(dist))
        if s > p.length:
            ex, ey = xy[-1]
            cross = -(x - ex) * math.sin(psi) + (y - ey) * math.cos(psi)
            self._dist = abs(cross)
        return s, float(cross)

    def step(self, pose) -> FollowerOutput:
        """One control cycle from the pose estimate (x, y, theta); returns the command to send."""
        L = self.limits
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        pieces = self.path.pieces
        rev = self.reverse != (bool(pieces[self.k].reverse) if pieces and self.k < len(pieces) else False)
        if rev:
            th = wrap(th + math.pi)  # drive the back first: the follower works on the flipped heading
        cross = herr = 0.0
        remaining = 0.0
        v_t = w_t = 0.0
        passed_end = False
        if self.phase in ("turn", "drive") and pieces:
            p = pieces[self.k]
            s, cross = self._project(p, x, y)
            if self._dist > L.max_off_path:  # lost the path: stop following it, the caller re-plans
                self.stop()
                return FollowerOutput(-self.v if rev else self.v, self.w, False, "done", self.k, cross, 0.0, 0.0,
                                      off_path=self._dist)
            to_end = p.length - s
            last = self.k == len(pieces) - 1
            remaining = max(to_end, 0.0) + sum(q.length for q in pieces[self.k + 1:])
            if to_end <= L.position_tolerance and not last and self.v == 0.0:
                self.k += 1  # stopped at a corner (a turn in place next) or a change of direction
                self._i = 0
                self.phase = "drive" if self.no_spin else "turn"
                return self.step(pose)
            if last and (to_end <= L.position_tolerance or (self.end_speed > 0.0 and to_end <= self.v * self.dt / 2)):
                if self.end_speed > 0.0:
                    passed_end = True
                    self.phase = "done"
                else:
                    self.phase = "final_turn" if self.final_heading is not None else "done"
            else:
                _, _, psi, _ = p.at(s)
                aim = psi + math.atan2(-cross, L.lookahead)
                herr = wrap(aim - th)
                if self.phase == "turn" and self._turned(herr, remaining):
                    self.phase = "drive"
                # driving, only a heading far off the path's stops it (the cross-track aim alone does not)
                if abs(herr) > L.heading_tolerance and not self.no_spin and (
                        self.phase == "turn" or self.v == 0.0 or abs(wrap(psi - th)) > 2 * L.heading_tolerance):
                    self.phase = "turn"
                if self.phase == "drive":
                    prof = self._prof[self.k]
                    ahead = s + self.v * self.dt
                    v_allowed = float(np.interp(ahead, p.s, prof)) if len(p.s) > 1 else 0.0
                    # the profile only tends to 0 at a stop: the last millimetres at CREEP_SPEED at least (else a
                    # pose that follows the command exactly crept on for seconds before the next piece's turn)
                    v_allowed = max(v_allowed, CREEP_SPEED)
                    v_t = min(v_allowed, max(to_end, 0.0) / self.dt if not (last and self.end_speed > 0) else v_allowed)
                    v_t *= max(0.0, math.cos(herr))
                    # feed-forward: the curvature where the robot will be once w has changed
                    kap = self._feed_forward_curvature(p, s, max(self.v, v_t))
                    v_ff = max(self.v, 0.0)
                    w_t = v_ff * kap + self._turn_rate(herr, drive=True)
                    w_t = max(-L.w_max, min(L.w_max, w_t))
                    if self.no_spin:  # turning only as much as the speed allows: an arc, never a spin
                        cap = L.spin_curvature * max(self.v, v_t) + L.spin_slack
                        w_t = max(-cap, min(cap, w_t))
                    # the outer wheel within v_wheel: the steering keeps its turn rate, the speed gives way
                    v_t = max(0.0, min(v_t, L.v_wheel - abs(w_t) * L.half_track))
                elif self.v == 0.0:  # turning in place only once stopped
                    w_t = self._turn_rate(herr)
        if self.phase == "final_turn":
            target = self.final_heading if not rev else wrap(self.final_heading + math.pi)
            herr = wrap(target - th)
            if abs(herr) <= L.heading_goal_tolerance and abs(self.w) <= L.alpha_max * self.dt:
                self.phase = "done"
            else:
                w_t = self._turn_rate(herr)
        if passed_end:
            v_t, w_t = self.v, self.w  # hand over at speed: the caller's next manoeuvre continues
        if self.phase in ("turn", "final_turn") and self.v == 0.0:
            if not self._spinning:  # a turn on the spot begins: how far it goes sets its rate
                self._spinning = True
                long = L.long_spin > 0 and L.w_long_spin > 0 and abs(herr) > L.long_spin
                self._spin_cap = L.w_long_spin if long else math.inf
            w_t = max(-self._spin_cap, min(self._spin_cap, w_t))
        else:
            self._spinning = False
        # acceleration limits
        self.v = ramp(self.v, v_t, L.a_max * self.dt)
        self.w = ramp(self.w, w_t, L.alpha_max * self.dt)
        if self.phase == "done" and not passed_end and abs(self.v) < 1e-9 and abs(self.w) < 1e-9:
            self.v = self.w = 0.0
        v_out = -self.v if rev else self.v
        done = self.phase == "done" and (passed_end or (self.v == 0.0 and self.w == 0.0))
        return FollowerOutput(v_out, self.w, done, self.phase, self.k, cross, herr, remaining)

    def _feed_forward_curvature(self, p: Piece, s: float, v: float) -> float:
        """The path's curvature averaged over a window centred a command delay ahead, as long as the
        distance the turn rate needs to ramp up to an arc's (alpha_max): the turn rate then rises half a
        window before an arc and falls half a window before its end, and the heading at the end is the
        path's (the mean keeps the arc's total turn) instead of lagging behind it (1/m)."""
        L = self.limits
        c = s + L.ff_lead * v * self.dt  # the command's delay through the wheels' speed controllers
        i0 = int(np.searchsorted(p.s, c - 0.3))
        i1 = int(np.searchsorted(p.s, c + 0.3))
        k_near = float(np.max(np.abs(p.kappa[i0:i1 + 1]))) if i1 > i0 else 0.0
        window = v * v * min(k_near, L.w_max / max(v, 1e-6)) / L.alpha_max  # m the ramp takes
        if window <= 0.005:
            return p.at(c)[3]
        ss = np.linspace(c - window / 2, c + window / 2, 7)
        return float(np.mean(np.interp(ss, p.s, p.kappa)))

    def _turned(self, herr: float, remaining: float) -> bool:
        """A turn on the spot is over: within ``heading_tolerance`` / 2 of the aim, or with ``spin_settle``
        (and at most ``spin_settle_within`` m of path left) within that and stopped (the turn rate down to one
        cycle's ramp)."""
        L = self.limits
        if L.spin_settle > 0 and (L.spin_settle_within <= 0 or remaining <= L.spin_settle_within):
            return abs(herr) <= L.spin_settle and abs(self.w) <= L.alpha_max * self.dt
        return abs(herr) <= L.heading_tolerance / 2

    def _turn_rate(self, err: float, drive: bool = False) -> float:
        L = self.limits
        if drive:  # a correction on top of the feed-forward
            return math.copysign(min(L.w_max, L.k_drive * abs(err)), err)
        # braking-distance limited so an in-place turn stops on the heading
        return spin_rate(err, L.w_max, L.k_heading, 0.05, L.alpha_max) if abs(err) > 1e-4 else 0.0
