"""What ``raf experiment competition`` measures from the ground truth of a run, cycle by cycle, the same in
both modes: fed from the in-process simulator (bare_truth) or from ``raf sim --trace`` (full_stack).

Per run: collision checks that hit (the robot's outline, and a held part's at its real pose once it is 3 cm or
more from every slot centre, against walls and ribs or beyond the floor's 2 cm overhang allowance, every 5
cycles), parts knocked out of slots (a part more than 3 cm from every slot centre that was within 3 cm of one
at the check before, not on the magnet then or now: the issue's target is none), parts pushed (stricter: a part
not on the magnet moving 2 mm - 5 cm within 5 cycles: a push, not a machine's teleport), where each part was let
go (its offset from the nearest slot's normal, the line through the slot's centre along its facing: how far
beside its slot the agent put it), the wheel odometry's error against the truth over each
second per metre driven, how far each turn on the spot with a part went beyond the odometry's (``carry_turn_slip_deg``:
the truth's heading change less the odometry's from the turn's start to ``SPIN_AFTER`` s after its end, positive
where the robot turned farther, turns of at least ``SPIN_MIN`` only; the turn told by the odometry's speeds; and
``carry_turn_deg``, the size of each of those turns by the truth, so that the slip can be put per degree turned, and
``carry_turn_end_s``, when each ended, so that the whole stack's estimate can be read after it), the time split
per agent activity (when the caller knows it), and for the figures the path and the animation frames.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

CHECK_EVERY = 5  # cycles between collision and push checks (and path samples)
RELEASE_NEAR = 0.1  # m: a part let go farther than this from every slot's centre was dropped, not placed
SLIP_EVERY = 25  # cycles per odometry-slip interval (1 s)
SPIN_AFTER = 0.5  # s after a turn on the spot with a part ends: its slip is measured then (the robot slides on)
SPIN_MIN = math.radians(20)  # rad: shorter turns on the spot are not measured
SPIN_V, SPIN_W = 0.02, 0.3  # m/s, rad/s: a turn on the spot by the odometry's speeds (|v| below, |w| above)


@dataclass
class _Spin:
    """A turn on the spot with a part being followed: the odometry's and the truth's headings at its start (rad)
    and when it ended (s; None while turning)."""

    odometry0: float
    truth0: float
    ended: float | None = None


class RunObserver:
    """Feed :meth:`cycle` after every control cycle; :meth:`figures` gives the run's keys."""

    def __init__(self, field, robot, record_path: bool = False):
        from ..agent.footprint import PLATE_THICKNESS, Footprint, Rect, robot_footprint
        from ..agent.obstacles import FieldObstacles
        from ..localization.odometry import DiffDriveOdometry

        self.walls = FieldObstacles(field, [])
        self.fp = robot_footprint(robot)
        p = field.part  # a part in its own frame: the plate towards +x (its pose's heading is the plate's facing)
        self.part_outline = Footprint((Rect(-p.depth / 2, p.depth / 2 + PLATE_THICKNESS, -p.width / 2, p.width / 2),))
        self.slots = list(field.slots)
        self.slot_xy = [s.xy for s in self.slots]
        self.period = robot.control_period
        self.record_path = record_path
        self.touched = self.off_floor = self.pushed = self.knocked_out = 0
        self.knocks: list[tuple] = []  # (t, part id, x, y): a part that left a slot without being held
        self._in_slot: dict[int, bool] = {}
        self.hits: list[tuple] = []  # (t, x, y, "wall" | "floor")
        self.pushes: list[tuple] = []  # (t, x, y, mm moved, activity)
        self.path: list[tuple] = []
        self.frames: list[tuple] = []
        self.split: dict[str, float] = {}
        self._last_xy: dict[int, tuple] = {}
        self.releases: list[tuple] = []  # (t, part id, nearest slot, offset from its normal m, from its centre m)
        self._held_before: int | None = None
        self._odo = DiffDriveOdometry(robot)
        self._odo_started = False
        self._prev = None
        self.slip: list[tuple] = []  # per second: (position error m, heading error rad, truth's length m, t)
        self.twist = (0.0, 0.0)  # odometry's latest body speeds (m/s, rad/s)
        self._spin: _Spin | None = None  # a turn on the spot with a part being followed
        self.carry_turn_slip: list[float] = []  # deg per such turn (see the module docstring)
        self.carry_turn: list[float] = []  # deg: each such turn's size by the truth (unsigned)
        self.carry_turn_end: list[float] = []  # s: when each such turn ended (its slip is measured SPIN_AFTER later)

    def cycle(self, t: float, seq: int, pose, held: int | None, enc, parts, activity: str | None = None) -> None:
        """One control cycle's truth: time, cycle number, robot pose, the held part's id, the encoder totals,
        the parts' poses (``{id: (x, y, theta)}`` or a callable giving it, read every 5 cycles only) and the
        agent's activity (None: unknown)."""
        if activity is not None:
            self.split[activity] = self.split.get(activity, 0.0) + self.period
        if self._held_before is not None and held != self._held_before:  # let go (read on the cycle it happens)
            released = (parts() if callable(parts) else parts).get(self._held_before)
            if released is not None:
                self.releases.append((round(t, 2), self._held_before, *self._release_offset(released)))
        self._held_before = held
        if not self._odo_started:
            self._odo.reset(baseline=tuple(enc), t=t)
            self._odo_started = True
        else:
            o = self._odo.update(enc[0], enc[1], t)
            self.twist = (o.v, o.w)
            self._carry_turn(t, o, pose, held)
            if seq % SLIP_EVERY == 0:
                now = ((o.x, o.y, o.theta), tuple(pose))
                if self._prev is not None:
                    self.slip.append(relative_error(self._prev, now) + (round(t, 2),))
                self._prev = now
        if seq % CHECK_EVERY:
            return
        x, y, th = pose
        parts = parts() if callable(parts) else parts
        # the robot's outline, and a held part where it really is once it has left its slot (in a slot it
        # stands between ribs, against the back: not a collision; the robot's outline checks the approach)
        checks = [(self.fp, pose)]
        if held is not None and held in parts and self._out_of_slot(parts[held]):
            checks.append((self.part_outline, parts[held]))
        hit = next((c for c in checks if self.walls.collides(*c)), None)
        if hit is not None:  # a wall, a rib or beyond the floor's allowance
            self.touched += 1
            hit_wall = self.walls.collides(*hit, ignore_floor=True)
            self.off_floor += not hit_wall
            kind = ("wall" if hit_wall else "floor") + (" (the held part)" if hit[0] is self.part_outline else "")
            self.hits.append((round(t, 2), round(x, 3), round(y, 3), kind))
        if self.record_path:
            self.path.append((round(t, 3), round(x, 4), round(y, 4)))
            # for the animated picture (_competition_gif): pose with heading, held part, parts
            self.frames.append((round(t, 2), round(x, 4), round(y, 4), round(th, 3), held,
                                [(pid, *(round(v, 3) for v in p)) for pid, p in sorted(parts.items())]))
        for pid, pp in parts.items():
            inside = not self._out_of_slot(pp)
            if self._in_slot.get(pid) and not inside and held != pid and self._last_xy.get(pid, (0, 0, ""))[2] != "held":
                self.knocked_out += 1  # out of its slot, not on the magnet: knocked out (a machine moves slot to slot)
                self.knocks.append((round(t, 2), pid, round(pp[0], 3), round(pp[1], 3)))
            self._in_slot[pid] = inside
        for pid, (px, py, _) in parts.items():
            last = self._last_xy.get(pid)
            if last is not None and held != pid:
                d = math.hypot(px - last[0], py - last[1])
                if 0.002 < d < 0.05 and last[2] != "held":
                    self.pushed += 1
                    self.pushes.append((round(t, 2), round(px, 3), round(py, 3), round(1000 * d, 1), activity))
            self._last_xy[pid] = (px, py, "held" if held == pid else "")

    def _carry_turn(self, t: float, o, pose, held) -> None:
        """Follow turns on the spot with a part (the odometry's speeds): at ``SPIN_AFTER`` s after one ends, how
        far the truth turned beyond the odometry (deg, positive: farther, in the turn's direction)."""
        on = held is not None and abs(o.v) < SPIN_V and abs(o.w) > SPIN_W
        spin = self._spin
        if spin is None:
            if on:
                self._spin = _Spin(o.theta, pose[2])
            return
        if on:
            spin.ended = None  # (still turning, or turning again before the slip was measured: one turn)
            return
        if spin.ended is None:
            spin.ended = t
        if t < spin.ended + SPIN_AFTER:
            return
        self._spin = None
        truth = math.remainder(pose[2] - spin.truth0, 2 * math.pi)
        if abs(truth) >= SPIN_MIN:
            slip = math.remainder(truth - (o.theta - spin.odometry0), 2 * math.pi)
            self.carry_turn_slip.append(round(math.degrees(math.copysign(1.0, truth) * slip), 3))
            self.carry_turn.append(round(math.degrees(abs(truth)), 3))
            self.carry_turn_end.append(round(spin.ended, 3))

    def _release_offset(self, part_pose) -> tuple[str, float, float]:
        """The slot nearest to a part let go at ``part_pose``: its name, the part's signed offset from the slot's
        normal (m, positive to the left of the facing) and its distance from the slot's centre (m)."""
        x, y = part_pose[0], part_pose[1]
        slot = min(self.slots, key=lambda s: math.hypot(x - s.xy[0], y - s.xy[1]))
        dx, dy = x - slot.xy[0], y - slot.xy[1]
        return slot.name, -dx * math.sin(slot.facing) + dy * math.cos(slot.facing), math.hypot(dx, dy)

    def _out_of_slot(self, part_pose, within: float = 0.03) -> bool:
        return all(math.hypot(part_pose[0] - sx, part_pose[1] - sy) > within for sx, sy in self.slot_xy)

    def figures(self) -> dict:
        """The run's keys (see the module docstring); ``path`` and ``frames`` when recording."""
        moved = sum(s[2] for s in self.slip)
        out = {"collision_checks_hit": self.touched, "off_floor_checks": self.off_floor, "collision_hits": self.hits,
               "parts_pushed": self.pushed, "pushes": self.pushes,
               "parts_knocked_out": self.knocked_out, "knocks": self.knocks,
               "releases": [(t, pid, name, round(off, 4), round(d, 4)) for t, pid, name, off, d in self.releases],
               "release_offsets_m": [round(abs(r[3]), 4) for r in self.releases if r[4] <= RELEASE_NEAR],
               "odometry_error_per_m": sum(s[0] for s in self.slip) / moved if moved > 0 else 0.0,
               "odometry_error_max_per_s_m": max((s[0] for s in self.slip), default=0.0),
               "odometry_heading_error_max_per_s_rad": max((s[1] for s in self.slip), default=0.0),
               "carry_turn_slip_deg": list(self.carry_turn_slip), "carry_turn_deg": list(self.carry_turn),
               "carry_turn_end_s": list(self.carry_turn_end)}
        if self.split:
            out["time_split"] = {k: round(v, 2) for k, v in sorted(self.split.items())}
        if self.record_path:
            out["path"], out["frames"] = self.path, self.frames
        return out


def relative_error(prev, now) -> tuple[float, float, float]:
    """Odometry against the truth over one interval: the position (m) and heading (rad) error of the
    odometry's motion expressed in its own start frame, and the truth's distance (m). Wheel slip (SimTwo's
    PID has no ramp: harsh acceleration slips the tyres) shows here; ground truth as the pose hides it."""
    from ..localization.geometry import between2, wrap_angle

    (o0, t0), (o1, t1) = prev, now
    ro, rt = between2(o0, o1), between2(t0, t1)
    dth = wrap_angle(ro[2] - rt[2])
    return math.hypot(ro[0] - rt[0], ro[1] - rt[1]), abs(dth), math.hypot(rt[0], rt[1])
