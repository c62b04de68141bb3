"""A part dropped on the floor, found with the LIDAR and picked up again (``recovery.refind``; docs/agent.md, "A
part dropped on the floor"): the floor recovery of the round's behaviour, apart from its state machine.

:class:`FloorRecovery` holds the part being recovered (:class:`LostPart`), the parts left on the floor, the search
and the floor pick's own :class:`~.docking.Docker`; the state machine (:class:`~.behaviour.RoundAgent`, modes
``search``, ``to_floor``, ``floor_pick``) owns it, hands it the round's changing state as arguments and does what
it answers (:class:`Next`): look again, decide again, plan the leg to the part, start that leg, drive clear first.
It never changes the state machine's mode itself.

* **Noticed** (:meth:`FloorRecovery.fell`, :meth:`FloorRecovery.let_go`): where it fell is the held part's centre
  (:func:`~.refind.lost_spot`).
* **Found** (:meth:`FloorRecovery.look`): standing still, in the first LIDAR sweep taken since
  (:func:`~.refind.find_part`); seen far to the side, after a turn on the spot towards it; a part the server now
  lists in a slot near where it fell landed there.
* **Picked up** (:meth:`FloorRecovery.plan`, :meth:`FloorRecovery.start_dock`): a leg to an approach pose facing its
  plate, then the docker's pick at ``refind_speed``.
* **Given up** (:meth:`FloorRecovery.failed`) after ``refind_tries``: left where it lies, an obstacle for legs with
  a part on the magnet (:meth:`FloorRecovery.obstacles`).

Plain Python, no ROS. Frames and units: the field frame, metres, radians, seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Callable

from ..competition.parts import PartType
from .docking import Docker, DockSettings
from .follower import DriveLimits, ramp, spin_rate
from .footprint import pose_in_front, wrap
from .legs import LegPlan, LegPlanner
from .obstacles import FieldObstacles, PartObstacle
from .planner import NoPath
from .refind import FloorSlot, FoundPart, Scan, find_part, lost_spot
from .settings import AgentSettings
from .state import FactoryState, SlotRef
from .tasks import Move


#: m a floor pick backs out at least, past the dock pose: then the contact switch (1 cm beam) is clear of a part
#: that was touched but not held (in the open the carrying approach distance is the dock pose itself)
FLOOR_BACK_OUT = 0.025
#: rad: a part on the floor is approached along its plate's normal or, where that line is not clear (the part by a
#: rib), this much to either side of it: the magnet's ray still meets the 8 cm plate, which it pulls flat
FLOOR_SLANTS = (0.0, 0.3, -0.3)
#: The search's turn on the spot towards where to look (:func:`.follower.spin_rate`, ramped at alpha_max like the
#: follower's and the re-localization's turns): at most SEARCH_TURN_W rad/s, SEARCH_TURN_GAIN rad/s per rad of
#: heading error, its braking planned at SEARCH_TURN_BRAKE x alpha_max (a 30 % margin on the braking,
#: against overshooting the heading). Softer than the follower's turns on the spot (w_max 3 rad/s on the SimTwo
#: robot, k_heading 8, the whole alpha_max): the turn is for a look and must end standing on the heading, not past
#: it. These are the values the floor recovery was measured with (``raf bench drops``, docs/agent.md); they were
#: not tuned apart.
SEARCH_TURN_W = 1.2
SEARCH_TURN_GAIN = 4.0
SEARCH_TURN_BRAKE = 0.7
#: rad and rad/s: the turn has arrived within SEARCH_TURN_TOLERANCE of the heading (the re-localization's
#: tolerance too: the LIDAR needs the part roughly ahead, not exactly) and turning slower than SEARCH_TURN_SETTLED
#: (less than one cycle's change of the turn rate, alpha_max x dt: 0.47 rad/s on the SimTwo robot, so the
#: braking that follows takes a cycle)
SEARCH_TURN_TOLERANCE = 0.05
SEARCH_TURN_SETTLED = 0.2
#: s a search's turn may take before the robot looks from where it stands: about twice its longest turn (a half
#: turn at these rates: 2.9 s); one that has not arrived by then is held up
SEARCH_TURN_TIME = 6.0


@dataclass
class LostPart:
    """A part that fell off the magnet: its type, where it fell (``spot``: :func:`~.refind.lost_spot`, the plate's
    heading then first), when (``t``, s), the destination it was going to, the state the agent expected then
    (to tell a part that landed in a slot), where it is taken to lie now (``where``), floor picks tried, the
    faces touched but not held."""

    part: PartType
    spot: FoundPart
    t: float
    dest: SlotRef | None
    state: FactoryState | None
    where: FoundPart | None = None
    tries: int = 0
    held_not: list = field(default_factory=list)  # plate headings (rad) tried that the magnet did not hold


@dataclass
class _Search:
    """Where the search for a lost part is: ``stop`` (braking), ``look`` (standing, waiting for a sweep taken
    since ``still``), ``turn`` (towards ``heading``, to look again)."""

    phase: str = "stop"
    still: float = 0.0
    turned: bool = False
    heading: float = 0.0


@dataclass(frozen=True)
class Next:
    """What the state machine does next with the lost part (:class:`FloorRecovery`'s answers), ``to``:

    * ``search``: stop and look for it (again);
    * ``decide``: it is dealt with (left on the floor, or it landed in a slot): decide again;
    * ``to_floor``: plan the leg to it (:meth:`FloorRecovery.plan`) from here;
    * ``failed``: a failed try, for ``reason`` (:meth:`FloorRecovery.failed`);
    * ``leg``: drive ``leg``, planned to the approach pose facing its plate (mode ``to_floor``);
    * ``escape``: first drive straight to ``point``, forwards or backwards, never turning on the spot (standing too
      close to it to turn);
    * ``no_path``: no leg to it (the state machine's usual handling of a leg without a path)."""

    to: str
    reason: str = ""
    leg: LegPlan | None = None
    point: tuple[float, float] | None = None


class FloorRecovery:
    """See the module docstring. ``settings``, ``limits``, ``dt``, ``legs``: the state machine's (its leg planner
    plans the legs to the part); ``dock``: its docking settings (the floor pick approaches at ``refind_speed``);
    ``counters`` (:class:`~.behaviour.AgentCounters`) and ``event(t, text)``: its counters and log.
    ``obstacles()``: the field as legs are planned on now (the floor's parts of :meth:`obstacles` included);
    ``mapped(floor)``: the last state's parts, the blocked spots and ``floor`` (parts lying on the floor)."""

    def __init__(self, field, robot, settings: AgentSettings, limits: DriveLimits, dt: float, legs: LegPlanner,
                 dock: DockSettings, counters, event: Callable[[float, str], None],
                 obstacles: Callable[[], FieldObstacles], mapped: Callable[[list], FieldObstacles]):
        self.field, self.robot, self.settings = field, robot, settings
        self.limits, self.dt, self.legs = limits, float(dt), legs
        self.counters, self._event, self._obstacles, self._mapped = counters, event, obstacles, mapped
        # a part on the floor: no ribs to guide it, nothing behind it; approached slower, the magnet on early
        self.docker = Docker(limits, dt, float(robot.electromagnet["x"]), field.part,
                             replace(dock, v_dock=settings.recovery.refind_speed, pick_gate=0.0))
        self.lost: LostPart | None = None  # a part that fell off the magnet, being recovered
        self.left: list[PartObstacle] = []  # lost parts left on the floor: obstacles while carrying
        self.pick_lost: LostPart | None = None  # a pick that let its part go: on the floor if not in its slot
        self.place_lost: LostPart | None = None  # a place just done: near its slot if the server does not list it
        self._slot: FloorSlot | None = None  # the floor part being picked, as a slot
        self._search = _Search()
        self._retreat = 0.0  # m from the floor part's centre the floor pick backs out to

    # ------------------------------------------------------------------------------------------ noticed
    def fell(self, t: float, part: PartType, held_pose, dest: SlotRef | None, state: FactoryState | None) -> None:
        """The carried ``part`` fell off the magnet on the way to ``dest``: it fell where it was held at
        ``held_pose`` (the last pose at which the contact switch showed it). The search starts next."""
        spot = lost_spot(held_pose, self.docker.magnet_x, self.field.part)
        self.lost = LostPart(part, spot, t, dest, state)
        self._event(t, f"looking for it: it fell near ({spot.x:.3f}, {spot.y:.3f})")

    def let_go(self, t: float, part: PartType, pose, slot, dest: SlotRef | None, state: FactoryState | None) -> None:
        """A pick of ``part`` from ``slot`` (the field's) held it, then let it go backing out to ``pose``: if the
        server no longer lists it in its slot (:meth:`let_go_missing`), it lies on the floor between the slot and
        the robot, its plate towards the robot."""
        self.pick_lost = LostPart(part, self._let_go_at(pose, slot), t, dest, state)

    def let_go_missing(self, t: float, task, state: FactoryState) -> bool:
        """A state seen since a pick let its part go (:meth:`let_go`): True when the server no longer lists it in
        the slot of ``task`` (it is on the floor: the search starts next); False when it is still there (the usual
        retry)."""
        lost, self.pick_lost = self.pick_lost, None
        if not (isinstance(task, Move) and state.at(task.source) is None):
            return False
        return self._missing(t, lost, f"lost the {lost.part.label} part picking it at {task.source}: the server no "
                                      f"longer lists it there")

    def placed(self, t: float, part: PartType, pose, dest: SlotRef, state: FactoryState | None) -> None:
        """``part`` was placed in ``dest``, the magnet letting go at ``pose``: if the next state
        does not list it there (:meth:`place_missing`), it lies near the slot (turned in it, or out of it on the
        floor), its plate towards where the robot was. ``state``: the state as the agent knew it before."""
        slot = self.field.slot(dest.zone, dest.number)
        self.place_lost = LostPart(part, self._let_go_at(pose, slot), t, dest, state)

    def place_missing(self, t: float, state: FactoryState) -> bool:
        """The first state seen since a place (:meth:`placed`): True when the server does not list the part in the
        slot it was placed in (the search starts next); False when it does. (A machine takes a part from its input
        only after processing it, seconds later: the first state after the place still shows it there.)"""
        lost, self.place_lost = self.place_lost, None
        if lost is None or state.at(lost.dest) is not None:
            return False
        return self._missing(t, lost, f"the {lost.part.label} part is not in {lost.dest} after the place: the server "
                                      f"does not list it")

    def _let_go_at(self, pose, slot) -> FoundPart:
        """Where a part the magnet let go of at a slot lies: in front of the magnet at ``pose``, its plate facing
        as the slot's."""
        spot = lost_spot(pose, self.docker.magnet_x, self.field.part)
        return FoundPart(spot.x, spot.y, (slot.facing,))

    def _missing(self, t: float, lost: LostPart, what: str) -> bool:
        """``lost`` is on the floor (``what`` says why): counted, logged, and the part the search looks for."""
        self.counters.parts_lost += 1
        self._event(t, f"{what}; looking for it near ({lost.spot.x:.3f}, {lost.spot.y:.3f})")
        self.lost = lost
        return True

    # ------------------------------------------------------------------------------------------ found
    def start_search(self) -> None:
        """Look for the lost part from the next cycle (:meth:`look`), the robot braking to a stop."""
        self._search = _Search()
        self._slot = None
        if self.lost is not None:
            self.lost.where = None  # until this search says

    def look(self, t: float, pose, v: float, w: float, scan: Scan | None, state: FactoryState | None,
             state_time: float) -> float | Next | None:
        """One cycle of looking for the lost part, ``v``, ``w`` the speeds commanded last cycle: brake to a stop;
        take the first LIDAR sweep measured since the robot stands (waiting at most ``refind_scan_wait`` s; none
        given: at once); the part seen far to the side (where the robot's own wheels hide part of it), turn towards
        it once and look again. Returns None (brake), a turn rate (rad/s, turning on the spot) or the search's
        outcome (:meth:`_found`)."""
        s, rc = self._search, self.settings.recovery
        if s.phase == "stop":
            if abs(v) > 1e-9 or abs(w) > 1e-9:
                return None
            s.phase, s.still = "look", t
        if s.phase == "turn":
            err = wrap(s.heading - pose[2])
            if (abs(err) < SEARCH_TURN_TOLERANCE and abs(w) < SEARCH_TURN_SETTLED) or t - s.still > SEARCH_TURN_TIME:
                s.phase = "stop"
                return None
            L = self.limits
            want = spin_rate(err, min(L.w_max, SEARCH_TURN_W), SEARCH_TURN_GAIN, alpha_max=L.alpha_max,
                             brake=SEARCH_TURN_BRAKE)
            return ramp(w, want, L.alpha_max * self.dt)
        # look: a sweep measured after the robot stood still (its commands act command_latency later)
        since = s.still + self.settings.command_latency + self.dt
        fresh = scan is not None and scan.t0 >= since - 1e-9
        waited = t - s.still
        state_new = state_time >= self.lost.t
        if (not fresh or not state_new) and waited < rc.refind_scan_wait and (scan is not None or not state_new):
            return None
        found = None
        if fresh:
            found = find_part(scan, pose, self._lidar_mount(), self.lost.spot, self._obstacles_for_scan(state),
                              self.field.part, self.legs.footprint(False), self._search_radius(), rc.refind_margin)
            if found is not None and not s.turned:
                bearing = wrap(math.atan2(found.y - pose[1], found.x - pose[0]) - pose[2])
                if abs(bearing) > rc.refind_turn and self._can_turn_to(pose, pose[2] + bearing, found):
                    s.turned, s.phase, s.heading, s.still = True, "turn", wrap(pose[2] + bearing), t
                    self._event(t, f"LIDAR: something at ({found.x:.3f}, {found.y:.3f}), "
                                   f"{math.degrees(bearing):.0f} deg off the heading: turning to look at it")
                    return None
            if found is None and not s.turned:  # a part beside the robot may lie in its wheels' shadow
                for turn in (math.pi / 2, -math.pi / 2):
                    if self._can_turn_to(pose, pose[2] + turn, None):  # (not ahead, where the LIDAR sees)
                        s.turned, s.phase, s.heading, s.still = True, "turn", wrap(pose[2] + turn), t
                        self._event(t, "LIDAR: nothing near where it fell: a quarter turn to look past the wheels")
                        return None
        why = "no LIDAR" if scan is None else ("no sweep since it stopped" if not fresh else "nothing there")
        return self._found(t, found, why, state, state_time, seen_empty=fresh)

    def _search_radius(self) -> float:
        """m around where the part fell that a search looks: ``refind_radius``, wider on each later try (a part
        slides far on a smooth floor, or was pushed)."""
        return self.settings.recovery.refind_radius * (1 + self.lost.tries)

    def _lidar_mount(self) -> tuple[float, float]:
        xyz = self.robot.lidar.xyz
        return float(xyz[0]), float(xyz[1])

    def _obstacles_for_scan(self, state: FactoryState | None) -> FieldObstacles:
        """What the map explains in a sweep: walls, ribs, the parts the server lists and those left on the
        floor (not the blocked spots: something the map lacks, which may be the part itself)."""
        st = state if state is not None else FactoryState.from_letters("XXXX")
        return self.legs.obstacles(st, (), None, self.left)

    def _can_turn_to(self, pose, heading: float, part: FoundPart | None) -> bool:
        """The outline (5 mm margin) clears everything, ``part`` on the floor included (the lost part where the
        LIDAR saw it), at every 0.1 rad of the turn in place from ``pose`` to ``heading``."""
        seen = [PartObstacle(part.x, part.y, part.facings[0])] if part is not None else []
        ob = self._mapped(self.obstacles(carrying=False) + seen)  # (searching, nothing is carried)
        fp = self.legs.footprint(False).inflated(0.005)
        d = wrap(heading - pose[2])
        n = max(1, int(abs(d) / 0.1))
        return not any(ob.collides(fp, (pose[0], pose[1], pose[2] + d * k / n)) for k in range(n + 1))

    def _found(self, t: float, found: FoundPart | None, why: str, state: FactoryState | None, state_time: float,
               seen_empty: bool = False) -> Next:
        """The search's outcome: the part where the LIDAR saw it; a part the server lists in a slot near where it
        fell is left to the next decision; not seen in a sweep (``seen_empty``): a failed try (the next looks
        farther); no sweep at all: where it fell, both faces of the plate possible. Then a leg to pick it up."""
        lost = self.lost
        landed = self._landed_in(found or lost.spot, state, state_time)
        if landed is not None:
            self._event(t, f"the lost {lost.part.label} part is in {landed} (the server lists it): deciding again")
            self.lost = None
            return Next("decide")
        if found is not None:
            self.counters.parts_refound += 1
            d = math.hypot(found.x - lost.spot.x, found.y - lost.spot.y)
            self._event(t, f"LIDAR: found the lost {lost.part.label} part at ({found.x:.3f}, {found.y:.3f}), "
                           f"{d * 100:.0f} cm from where it fell ({found.points} returns)")
        elif seen_empty:
            self._event(t, f"LIDAR: no part within {self._search_radius():.2f} m of where it fell")
            return Next("failed", reason="not seen")
        else:
            f0 = lost.spot.facings[0]
            found = FoundPart(lost.spot.x, lost.spot.y, (f0, wrap(f0 + math.pi)))
            self._event(t, f"LIDAR: {why}: picking it up where it fell ({found.x:.3f}, {found.y:.3f})")
        lost.where = found
        return Next("to_floor")

    def _landed_in(self, found: FoundPart, state: FactoryState | None, state_time: float) -> SlotRef | None:
        """A slot within ``refind_radius`` of where the part fell or was found that the server's state (asked
        since the loss) shows occupied and that was empty when it fell: the part landed there. Machine
        outputs are left out (a machine fills them)."""
        st, before = state, self.lost.state
        if st is None or before is None or state_time < self.lost.t:
            return None
        r = self.settings.recovery.refind_radius
        for zone in ("incoming", "machine_A", "machine_B", "outgoing"):
            for n, (now, then) in enumerate(zip(st.zone(zone), before.zone(zone)), start=1):
                slot = self.field.slot(zone, n)
                if now is None or then is not None or slot.role == "output":
                    continue
                if min(math.hypot(slot.xy[0] - p.x, slot.xy[1] - p.y) for p in (found, self.lost.spot)) <= r:
                    return SlotRef(zone, n)
        return None

    # ------------------------------------------------------------------------------------------ picked up
    def plan(self, t: float, pose, may_escape: bool) -> Next:
        """The leg to the lost part's approach pose, facing its plate (tries alternate between the two faces the
        LIDAR cannot tell apart; a face the magnet did not hold is not tried again), straight along the plate's
        normal or, where that line is not clear, at :data:`FLOOR_SLANTS` to it. Standing too close to the part to
        turn (and ``may_escape``), first drive straight away from it. No face left: it is left where it lies."""
        lost = self.lost
        facings = lost.where.facings
        order = [facings[(lost.tries + k) % len(facings)] for k in range(len(facings))]
        order = [f for f in order if not any(abs(wrap(f - w)) < 0.5 for w in lost.held_not)]
        if not order:
            return self._leave(t, "its plate faces where the robot cannot reach (the other side did not hold)")
        xy = (lost.where.x, lost.where.y)
        self._slot = FloorSlot(xy, order[0], plate=order[0])
        obstacles = self._obstacles()
        if may_escape:
            # standing next to it (it fell beside the robot): first straight away to where the robot may turn
            escape = self.legs.escape_point(obstacles, pose, False)
            if escape is not None:
                point = escape.xy
                self._event(t, f"too close to the part on the floor: driving to ({point[0]:.2f}, {point[1]:.2f}) "
                               "first")
                return Next("escape", point=point)
        err = None
        for plate in order:
            for slant in FLOOR_SLANTS:
                self._slot = FloorSlot(xy, wrap(plate + slant), plate=plate)
                obstacles = self._obstacles()
                try:
                    leg = self.legs.plan(obstacles, pose, self._slot, False, "pick")
                except NoPath as e:
                    err = e
                    continue
                d = math.hypot(leg.goal[0] - xy[0], leg.goal[1] - xy[1])
                far = max(d, self.legs.d_dock + FLOOR_BACK_OUT)
                if not self._line_clear(far):  # (a part lying by a wall: the approach pose beyond it)
                    err = NoPath(f"the straight approach from {far:.2f} m, plate towards "
                                 f"{math.degrees(plate):.0f} deg, is not clear")
                    continue
                self._retreat = far
                return Next("leg", leg=leg)
        self.counters.no_path += 1
        self._event(t, f"no path to the lost part at ({xy[0]:.3f}, {xy[1]:.3f}): {err}")
        return Next("no_path")

    def _line_clear(self, far: float) -> bool:
        """The empty outline (5 mm margin) is clear all along the straight line the floor pick drives and backs
        out on: from ``far`` m in front of the part (``_slot``) to its dock pose, the part itself left out."""
        fs, legs = self._slot, self.legs
        ob = self._mapped(self.obstacles(carrying=False, target=False))
        a, b = pose_in_front(fs, far), pose_in_front(fs, legs.d_dock)
        return legs.path_planner(ob, False).straight_clear(a[:2], b[:2], legs.footprint(False), 0.005) \
            and not ob.collides(legs.footprint(False).inflated(0.005), b)

    def start_dock(self, t: float, pose, v0: float) -> None:
        """The floor pick, from the leg's end at ``pose``, arriving at ``v0`` m/s."""
        fs = self._slot
        # back out along the line it came (checked clear), far enough to tell a held part from one only touched
        self.docker.start_pick(fs, pose, self._retreat, v0=v0)
        self._event(t, f"docking to pick the lost {self.lost.part.label} part from the floor at "
                       f"({fs.xy[0]:.3f}, {fs.xy[1]:.3f}), plate towards {math.degrees(fs.plate):.0f} deg"
                       f"{'' if fs.facing == fs.plate else f', from {math.degrees(wrap(fs.facing - fs.plate)):+.0f} deg'} "
                       f"(try {self.lost.tries + 1} of {self.settings.recovery.refind_tries})")

    def picked(self, t: float) -> LostPart:
        """Picked up from the floor: the part recovered (it is carried on as after any pick)."""
        lost = self.lost
        self.counters.floor_picks += 1
        self._event(t, f"picked the lost {lost.part.label} part up from the floor, {t - lost.t:.1f} s after it fell")
        self.lost, self._slot = None, None
        return lost

    # ------------------------------------------------------------------------------------------ given up
    def failed(self, t: float, reason: str) -> Next:
        """A floor pick (or the leg to it, or a search) failed: look again (it may have been pushed; the next try
        faces its other side), or after ``refind_tries`` leave it where it lies, an obstacle from now on."""
        lost = self.lost
        self.counters.floor_pick_failures += 1
        lost.tries += 1
        n = self.settings.recovery.refind_tries
        self._event(t, f"picking the lost {lost.part.label} part from the floor failed: {reason} "
                       f"(try {lost.tries} of {n})")
        if reason == "part_lost" and self._slot is not None:  # touched, not held: the plate is not there
            lost.held_not.append(self._slot.plate)
        if lost.tries < n:
            return Next("search")
        return self._leave(t, f"after {lost.tries} tries")

    def _leave(self, t: float, why: str) -> Next:
        """Give the lost part up: it stays where it lies, an obstacle from now on for legs with a part on the
        magnet (:meth:`obstacles`; planned through, the carried part hit it: a cascade of losses); the round goes
        on."""
        lost = self.lost
        w, fs = lost.where, self._slot
        if w is not None:  # (where the last search saw it or took it to be; not seen: nowhere known)
            self.left.append(PartObstacle(w.x, w.y, fs.plate if fs is not None else w.facings[0]))
        self.counters.parts_left += 1
        at = f" at ({w.x:.3f}, {w.y:.3f})" if w is not None else ""
        self._event(t, f"left the lost {lost.part.label} part on the floor{at}: {why}")
        self.lost, self._slot = None, None
        return Next("decide")

    def obstacles(self, carrying: bool, target: bool = True) -> list[PartObstacle]:
        """The parts lying on the floor that legs keep clear of: those left there while a part is carried (a
        carried part that hits one is knocked off; the empty robot may push one aside: kept clear of always, a part
        left in front of the incoming warehouse closed its slots, 12 points against 19 in the four runs where a
        part was left), and (``target``) the one being recovered."""
        out = list(self.left) if carrying else []
        if target and self._slot is not None:
            fs = self._slot
            out.append(PartObstacle(fs.xy[0], fs.xy[1], fs.plate))
        return out
