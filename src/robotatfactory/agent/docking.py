"""Docking: the final approach to a slot to pick its part, or to leave the carried part on it.

Both start at the slot's approach pose (:meth:`PathPlanner.approach_pose`), facing the plate, and end
there again after backing out. Each control cycle :meth:`Docker.step` takes the pose estimate (x, y, theta;
field frame, m, rad) and the contact switch, and returns body speeds and the electromagnet state.

**Pick:** drive straight along the slot's normal at ``v_dock`` towards the plate (aiming
``overshoot`` m past the dock pose so the contact is reached even with a pose error); once the contact
switch is pressed (the part's front face within its 1 cm beam, the magnet face within ~1 cm of the plate)
drive on to the dock pose for at most ``press_time`` s (a part standing out of its slot is pushed square
against the slot's back wall), stop, switch the electromagnet on, wait ``settle`` s, and back out to
``retreat`` m from the slot centre.
The contact switch stays pressed while a part hangs on the magnet (the part's body is in its beam), so it
is also the confirmation that the part came along: released after backing out = the part was lost.
No contact by the end of the approach: the robot backs out, then reports ``no_contact`` (the caller
retries or re-localizes).
An approach that has not met its part ``PICK_ENTRY`` m before the dock pose with base_link more than
``pick_gate`` m to the side of the slot's centre line goes no farther (the contact switch's bumper would go in
between the ribs): the robot backs out and reports ``off_line`` (the caller tries again from a fresh approach).

**Place:** drive straight to the place pose (the carried part's centre on the slot centre: the dock
distance with the magnet's hold gap), stop, electromagnet off, wait ``settle`` s, back out to ``retreat``.
The contact switch must be released once backed out (the part stayed); pressed = failure ``still_held``.
While the part is still outside the slot, a robot holding it more than ``place_gate`` m to the side of the
slot's centre line does not go in: it backs out along the normal to where the approach started, the part still
held, and reports ``off_line`` (the caller plans the place again; after ``place_gate_tries`` such stops in a
row it starts the place with ``gate=False``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .follower import DriveLimits, PathFollower
from .footprint import HOLD_GAP, PLATE_THICKNESS, pose_in_front, wrap
from .recovery import StuckDetector
from .settings import Carrying, Docking


#: m: the carried part's centre this far out from the slot's centre along its normal is where the part's front
#: meets the ends of a warehouse's ribs (3.5 cm out from the slot's centre; the part's half depth 3 cm): the place
#: gate (``DockSettings.place_gate``) looks at the part's offset until the part gets there
PLACE_ENTRY = 0.065
#: m out from the dock pose where a pick approach that has not met its part yet is looked at once by the pick gate
#: (``DockSettings.pick_gate``): past the dock pose the contact switch's bumper goes in between the slot's ribs
#: (12 mm clearance either side), and braking at the approach speed takes about 6 mm. (The contact switch is
#: reported a cycle or two after the predicted pose has passed it: the gate looks at nearly every pick.)
PICK_ENTRY = 0.006


@dataclass(frozen=True)
class DockSettings:
    """Speeds (m/s), distances (m), times (s) of the final approach. What the agent's settings also name
    (``dock.*``, :class:`~.settings.Docking`) takes its default from there: one default per setting."""

    v_dock: float = Docking.approach_speed  # pick approach (the contact switch stops it)
    v_place: float = Docking.place_speed  # place approach (to a pose, no contact needed; the part enters between ribs)
    overshoot: float = 0.01  # m past the dock pose the pick approach aims at (the contact stops it first)
    gap: float = 0.003  # m between the magnet face and the plate at the nominal dock pose
    settle: float = 0.1  # s standing still with the magnet switched on/off
    # m the place stops short of the part's centre on the slot's (a pose one cycle late overshoots by ~5 mm
    # and pressed the part against the slot's back: grazing hits; the rules allow 3 cm)
    place_short: float = 0.006
    v_back: float = 0.25
    v_back_carrying: float = 0.25  # m/s backing out of a slot with the part on the magnet
    # m/s^2 and m/s: backing out with the part, the speed ramps up and down at this rate and ends at this speed
    # (SimTwo's magnet let the part go when the robot set off at 2 m/s^2 and stopped from 0.25 m/s at once:
    # 5 of 12 picks lost on round 1, docs/simtwo.md "The agent on SimTwo")
    a_back_carrying: float = Carrying.back_accel
    v_back_carrying_final: float = 0.03
    lookahead: float = 0.12  # m: the approach steers onto the slot's normal (0.06: more grazing with a late pose)
    magnet_early: bool = Docking.magnet_early  # the magnet on from the approach's start (false: at the grip)
    # s the contact switch may take after backing out to show the outcome (part along / part left): it lags
    # the predicted pose by the loop's latency (80 ms on SimTwo and raf sim)
    confirm: float = 0.2
    compensate_offset: bool = True  # place with the robot as far off the slot's normal as it was at the pick
    # picking, after the contact the robot drives on to the dock pose (at most press_time s): a part standing out of
    # its slot, turned, is squared against the slot's back wall between it and the magnet's face instead of
    # pivoting on the face's edge (0: it stops at the contact)
    press_time: float = Docking.press_time
    # m: placing, the carried part's centre may be at most this far to the side of the slot's centre line while
    # the part is outside the slot (PLACE_ENTRY); farther off, the place is not entered: it backs out along the
    # normal and fails with "off_line" (0: off)
    place_gate: float = Docking.place_gate
    # m: picking, an approach that has not met the part by PICK_ENTRY m out from the dock pose, base_link more than
    # this to the side of the slot's centre line, backs out and fails with "off_line" (0: off; a floor pick: no ribs)
    pick_gate: float = Docking.pick_gate


@dataclass(frozen=True)
class DockOutput:
    """One cycle's command: body speeds (m/s, rad/s), the magnet, and where the manoeuvre is."""

    v: float
    w: float
    magnet: bool
    phase: str  # approach, press (picking), grip, release, back, confirm, done, failed
    done: bool = False
    failed: str | None = None  # no_contact, part_lost, still_held, blocked, timeout, off_line


class Docker:
    """Pick and place manoeuvres for one robot. ``magnet_x`` (m) is the magnet face in base_link;
    ``part`` the field's PartSpec; ``limits`` the normal drive limits (the docking speeds are lower)."""

    def __init__(self, limits: DriveLimits, dt: float, magnet_x: float, part, settings: DockSettings = DockSettings()):
        self.settings = settings
        self.dt = float(dt)
        self.magnet_x = float(magnet_x)
        self.part = part
        self.approach_limits = replace(limits, v_max=settings.v_dock, v_final=settings.v_dock, slow_distance=0.0,
                                       position_tolerance=0.002, lookahead=settings.lookahead)
        self.place_limits = replace(self.approach_limits, v_max=settings.v_place, v_final=settings.v_place)
        self.back_limits = replace(limits, v_max=settings.v_back, v_final=settings.v_back, slow_distance=0.0,
                                   position_tolerance=0.003)
        self.follower = PathFollower(self.approach_limits, dt)
        self.mode = "idle"
        self.phase = "done"
        self.magnet = False
        self._wait = 0.0
        self._slot = None
        self._retreat = 0.0
        self._start_along = 0.0  # m: base_link's distance from the slot's centre where the manoeuvre started
        self._failing: str | None = None
        self.stuck = StuckDetector(window=1.0, min_command=0.03, min_motion=0.008, min_rotation=0.03)
        self._steps = 0
        self.held_offset = 0.0  # m: the held part's centre to the right of the magnet's centre line, estimated
        self._shift = 0.0
        self._lateral: list[tuple[float, float, float]] = []  # picking: (base_link's, the centre line's) offsets, heading
        self._pick_gated = False  # picking: the pick gate has looked (it looks once)
        self._place_gated = True  # placing: the place gate looks (start_place's gate)

    # ------------------------------------------------------------------------------------------ geometry
    def dock_distance(self) -> float:
        """Slot centre to base_link when picking: the magnet face ``gap`` m from the plate (m)."""
        return self.part.depth / 2 + PLATE_THICKNESS + self.magnet_x + self.settings.gap

    def place_distance(self) -> float:
        """Slot centre to base_link when the carried part's centre is on the slot centre (m)."""
        return self.part.depth / 2 + PLATE_THICKNESS + self.magnet_x + HOLD_GAP + self.settings.place_short

    # ------------------------------------------------------------------------------------------ start
    def entry_speed(self, mode: str) -> float:
        """The speed (m/s) a path may arrive at the approach pose with when the manoeuvre follows on."""
        return self.settings.v_dock if mode == "pick" else self.settings.v_place

    def start_pick(self, slot, pose, retreat: float, v0: float = 0.0) -> None:
        """Pick the part in ``slot`` from ``pose`` (the approach pose, arriving at ``v0`` m/s); back out to
        ``retreat`` m from the slot centre afterwards."""
        self._begin("pick", slot, pose, retreat, self.dock_distance() - self.settings.overshoot, v0)
        self.magnet = self.settings.magnet_early

    def start_place(self, slot, pose, retreat: float, v0: float = 0.0, gate: bool = True) -> None:
        """Leave the carried part on ``slot``; the magnet stays on until the place pose is reached. ``gate``
        False: no place gate this time (``place_gate_tries`` gated places in a row)."""
        self._begin("place", slot, pose, retreat, self.place_distance(), v0)
        self._place_gated = bool(gate)
        self.magnet = True

    def _begin(self, mode: str, slot, pose, retreat: float, distance: float, v0: float = 0.0) -> None:
        self.mode, self._slot, self._retreat = mode, slot, float(retreat)
        self._failing = None
        self.stuck.reset()
        self._steps = 0
        self._shift = self.held_offset if mode == "place" and self.settings.compensate_offset else 0.0
        self._lateral = []
        self._pick_gated = False
        self._start_along = self._along(pose)
        target = self._shifted(pose_in_front(slot, distance))
        self.follower.limits = self.approach_limits if mode == "pick" else self.place_limits
        # from the point of the slot's normal nearest the robot: the approach follows the normal
        start = self._shifted(self._on_normal(pose))
        carrying = mode == "place"  # a part on the magnet: steer while driving, never turn on the spot
        self.follower.start([start, target[:2]], final_heading=None, no_spin=carrying)
        self.follower.v = max(0.0, min(float(v0), self.follower.limits.v_max))
        aligned = abs(wrap(pose[2] - target[2])) < 0.1
        self.follower.phase = "drive" if aligned or carrying else "turn"  # turning: it brakes, then turns in place
        self.phase = "approach"

    def _shifted(self, p):
        """``p`` (x, y[, theta]) moved sideways by the held part's offset: the robot's left of the approach
        (facing the slot) is (sin facing, -cos facing)."""
        f = self._slot.facing
        q = (p[0] + self._shift * math.sin(f), p[1] - self._shift * math.cos(f))
        return q + tuple(p[2:])

    def _base_offset(self, pose) -> float:
        """base_link's offset from the slot's normal, to its left (m; the robot facing the slot)."""
        s = self._slot
        return (pose[0] - s.xy[0]) * math.sin(s.facing) - (pose[1] - s.xy[1]) * math.cos(s.facing)

    def _lateral_offset(self, pose) -> float:
        """Where the robot's centre line crosses the slot's centre, to the left of the slot's normal (m; the robot
        facing the slot): base_link's offset plus what the heading adds over the distance to the slot's centre.
        Turned 7 deg, base_link 14 mm off the normal put the magnet's centre on the part; base_link's offset
        alone taken as the part's was placed 14 mm off (round 3 seed 100, docs/agent.md)."""
        return self._base_offset(pose) + self._along(pose) * math.tan(wrap(pose[2] - self._slot.facing - math.pi))

    def _along(self, pose) -> float:
        """base_link's distance from the slot's centre along its normal (m)."""
        s = self._slot
        return (pose[0] - s.xy[0]) * math.cos(s.facing) + (pose[1] - s.xy[1]) * math.sin(s.facing)

    def _off_line(self, pose) -> bool:
        """Placing, with the carried part still outside the slot (its centre more than ``PLACE_ENTRY`` out): the
        part's centre is more than ``place_gate`` m to the side of the slot's centre line. Where it is now, not
        where the steering would bring it: on SimTwo a robot that began a place 19 mm off and turned 4 deg
        away (the part 27 mm off) did not turn back before the part met the rib 0.2 s later, where a kinematic
        run of the approach has it 11 mm off at the ribs."""
        gate = self.settings.place_gate
        if gate <= 0 or self.phase != "approach" or not self._place_gated:
            return False
        lp = self.place_distance() - self.settings.place_short  # base_link to the held part's centre
        if self._along(pose) - lp <= PLACE_ENTRY:  # the part is at the ribs already: going back is no better
            return False
        psi = wrap(pose[2] - self._slot.facing - math.pi)  # the robot's turn from facing the slot
        # a leg ends on the slot's normal, so a part held farther off the magnet's centre line than the gate starts
        # that far off the slot's: the gate then stops only a place worse than that (else every place, for ever)
        gate = max(gate, abs(self._shift) + HELD_GATE_SLACK)
        return abs(self._base_offset(pose) - self._shift + lp * math.sin(psi)) > gate

    def _pick_off_line(self, pose) -> bool:
        """Picking, the approach not yet at its part ``PICK_ENTRY`` m out from the dock pose (looked at once, the
        first cycle there): base_link is more than ``pick_gate`` m to the side of the slot's centre line. A contact
        before that point is pressed on to the dock pose only, where the robot has 5 cm either side."""
        gate = self.settings.pick_gate
        if gate <= 0 or self.phase != "approach" or self._pick_gated:
            return False
        if self._along(pose) > self.dock_distance() + PICK_ENTRY:
            return False
        self._pick_gated = True
        return abs(self._base_offset(pose)) > gate

    def _on_normal(self, pose, ahead: float = 0.01) -> tuple[float, float]:
        """``pose`` brought onto the slot's normal, at least ``ahead`` m out from the dock pose."""
        s = self._slot
        u = (math.cos(s.facing), math.sin(s.facing))
        along = self._along(pose)
        if ahead:
            along = max(along, self.dock_distance() + ahead)
        return (s.xy[0] + along * u[0], s.xy[1] + along * u[1])

    # ------------------------------------------------------------------------------------------ step
    def step(self, pose, contact: bool) -> DockOutput:
        """One control cycle from the pose estimate and the contact switch."""
        if self.phase in ("approach", "press"):
            if self.stuck.update(self._steps * self.dt, pose, self.follower.v, 0.0):
                self.abort(pose, "blocked")  # driving, not moving: something is in the way (a rib, a part)
                return self._out(0.0, 0.0)
            self._steps += 1
            if self.mode == "place" and self._off_line(pose):
                # the part would meet a rib (SimTwo, round 1: 19 mm off and turned 4 deg, it fell beside the slot)
                self._retreat = max(self._retreat, self._start_along)  # back to where the leg ended: room to turn
                self.abort(pose, "off_line")
                return self._out(0.0, 0.0)
            if self.mode == "pick" and not contact and self._pick_off_line(pose):
                # the bumper would go in between the ribs off the line (stand-in, round 3: 19 mm off, it touched
                # machine A's rib): back out and try again from a fresh approach
                self.abort(pose, "off_line")
                return self._out(0.0, 0.0)
            out = self.follower.step(pose)
            if self.mode == "pick":
                self._lateral = (self._lateral + [(self._base_offset(pose), self._lateral_offset(pose),
                                                   float(pose[2]))])[-6:]
            if self.phase == "approach" and self.mode == "pick" and contact and self.settings.press_time > 0:
                self.phase, self._wait = "press", 0.0
            if self.phase == "press":  # on towards the wall, at most press_time s
                self._wait += self.dt
                if self._along(pose) > self.dock_distance() and self._wait < self.settings.press_time \
                        and not out.done:
                    return self._out(out.v, out.w)
            if self.mode == "pick" and (contact or self.phase == "press"):
                # the magnet holds the part where it met it: where the robot's centre line crosses the slot's
                # centre now is the part's offset from that line, to be repeated at the place (the mean of the last
                # cycles at the grip's heading: _held_offset)
                self.held_offset = _held_offset(self._lateral)
                if self.settings.compensate_offset:
                    # backing out along the normal through base_link as it stands: steering onto another line
                    # turns the robot in the slot and swings the part on the magnet (turned 5 deg at the grip,
                    # steering onto the centre line's swung it 13 mm sideways against 8: machine A's rib, round 3)
                    self._shift = sum(b for b, _, _ in self._lateral) / len(self._lateral)
                self.follower.stop()  # brake within the limits (a few mm at v_dock), magnet on at once
                self.phase, self._wait = "grip", 0.0
                self.magnet = True
                out = self.follower.step(pose)
                return self._out(out.v, out.w)
            if out.done:
                if self.mode == "pick":  # nothing there: magnet off, back out, then report
                    self._failing = "no_contact"
                    self.magnet = False
                    self._back(pose)
                    return self._out(0.0, 0.0)
                self.phase, self._wait = "release", 0.0
                self.magnet = False
                return self._out(0.0, 0.0)
            return self._out(out.v, out.w)
        if self.phase in ("grip", "release"):
            # brake with the limits, then stand still for `settle` seconds
            out = self.follower.step(pose)
            self._wait += self.dt
            if self._wait >= self.settings.settle and out.v == 0.0 and out.w == 0.0:
                self._back(pose)
            return self._out(out.v, out.w)
        if self.phase == "back":
            out = self.follower.step(pose)
            if out.done:
                if self._failing:
                    return self._fail(self._failing)
                self.phase, self._wait = "confirm", 0.0
            else:
                return self._out(out.v, out.w)
        if self.phase == "confirm":
            # the contact switch as the outcome; it may lag the pose: the pose is where the robot will be when
            # its command acts (raf agent predicts through the commands in flight), the switch where it was
            held = contact if self.mode == "pick" else not contact
            if held:
                self.phase = "done"
                return self._out(0.0, 0.0, done=True)
            out = self.follower.step(pose)
            self._wait += self.dt
            if self._wait > self.settings.confirm + 1e-9:
                return self._fail("part_lost" if self.mode == "pick" else "still_held")
            return self._out(out.v, out.w)
        return self._out(0.0, 0.0, done=self.phase == "done")

    def abort(self, pose, reason: str = "timeout") -> None:
        """Give up: magnet off when picking (on when placing: the part stays held), back straight out,
        then report ``reason``."""
        if self.phase in ("done", "failed"):
            return
        if self.mode == "pick":
            self.magnet = False
        self._failing = reason
        self._back(pose)

    def retreat_pose(self) -> tuple[float, float, float]:
        """Where the back-out of the manoeuvre under way ends (base_link x, y, theta: facing the slot, moved
        sideways by the held part's offset as the back-out is)."""
        return self._shifted(pose_in_front(self._slot, self._retreat))

    def _back(self, pose) -> None:
        """Back straight out along the slot's normal to ``retreat`` m from its centre."""
        back = pose_in_front(self._slot, self._retreat)
        s = self.settings
        self.follower.limits = self.back_limits if not self.magnet else replace(
            self.back_limits, v_max=min(self.back_limits.v_max, s.v_back_carrying),
            v_final=min(self.back_limits.v_final, s.v_back_carrying, s.v_back_carrying_final),
            a_max=min(self.back_limits.a_max, s.a_back_carrying))
        # along the slot's normal, from the point of it nearest the robot (a lateral error is steered out)
        self.follower.start([self._shifted(self._on_normal(pose, 0.0)), self._shifted(back)[:2]], reverse=True,
                            no_spin=self.magnet)  # backing out with the part: straight, no turn on the spot
        self.follower.phase = "drive"
        self.phase = "back"

    def _fail(self, reason: str) -> DockOutput:
        self.follower.stop()
        self.phase = "failed"
        return DockOutput(0.0, 0.0, self.magnet, "failed", False, reason)

    def _out(self, v: float, w: float, done: bool = False) -> DockOutput:
        return DockOutput(v, w, self.magnet, self.phase, done, None)


#: m: a place whose held part is farther off the magnet's centre line than ``place_gate`` is stopped by the gate
#: only where its part is more than this beyond that offset off the slot's centre line
HELD_GATE_SLACK = 0.005
#: rad: the pick's last samples within this of the heading at the grip describe where the part is held
HELD_HEADING = math.radians(0.5)


def _held_offset(samples: list[tuple[float, float, float]]) -> float:
    """The held part's offset from the robot's centre line at the grip (m; ``samples``: the pick's last (base_link's
    offset, the centre line's offset at the slot's centre, heading)): the mean centre line's offset of the trailing
    samples whose heading is within ``HELD_HEADING`` of the last one's. The part stays between the ribs while the
    robot squares up against it; the magnet takes it where the robot's centre line crosses it then. A mean over
    the robot's last turn into the slot took -17 mm for -9 (the stand-in, issue 20's conditions, round 2 seed
    110: 77-90 deg in the last 0.24 s), and every place after was stopped by the place gate."""
    th = samples[-1][2]
    run = []
    for _b, c, h in reversed(samples):
        if abs(math.remainder(h - th, 2 * math.pi)) > HELD_HEADING:
            break
        run.append(c)
    return sum(run) / len(run)
