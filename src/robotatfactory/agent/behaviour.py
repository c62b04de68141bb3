"""The round's behaviour: a per-cycle state machine that ties the task policy, the planner, the follower
and the docking together. No I/O and no clock of its own: the caller (the ROS node, or a test around the
bare simulator) feeds it every control cycle and polls the factory-state server for it.

Each cycle: :meth:`RoundAgent.step` (t in s, the pose estimate (x, y, theta) in the field frame or None when
it is stale, the contact switch) returns an :class:`AgentCommand` (body speeds, the magnet). Whenever
:attr:`RoundAgent.wants_state` is True the caller asks the server (IWP, OWP, MAP, MBP, CTL) and hands the
answer to :meth:`RoundAgent.on_state`; the agent decides only on a state seen after its last action
finished, so every decision is re-planned from what the server says. It does not move before it has
the part list (the first state).

Each leg (to a part, or carrying it to a slot) is planned by :class:`~.legs.LegPlanner` (:mod:`.legs`); the
state machine decides when to plan, starts the follower on the plan and handles a failure (re-plan, escape,
give up).

A part lost on the way (the contact switch released while carrying) is looked for and picked up from the
floor again (``recovery.refind``): the caller may hand the agent each LIDAR sweep (:meth:`RoundAgent.on_scan`,
optional). The modes ``search``, ``to_floor`` and ``floor_pick`` are the state machine's; their work (where it
fell, the search in a sweep, the leg to face its plate, the floor pick's docker, giving it up) is
:class:`~.floor.FloorRecovery`'s, which answers what to do next (docs/agent.md, "A part dropped on the floor").

Events (``events``: list of (t, text)) say what it did: the task chosen, picked, placed, failures.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field, replace

from ..competition.parts import PartType
from .ahead import Ahead
from .delay import DelayEstimator, lanes_of
from .docking import Docker, DockSettings
from .floor import FloorRecovery, LostPart, Next
from .follower import DriveLimits, PathFollower, ramp
from .hybrid import NoCarryPath
from .legs import VIA_RANKED, LegPlan, LegPlanner
from .obstacles import FieldObstacles, PartObstacle
from .order import LegTimes, Plan, leg_times, plan_order, table_key
from .planner import NoPath
from .recovery import Relocalizer, StuckDetector, uncertainty_of
from .refind import Scan
from .settings import PLACE_LOOK, AgentSettings
from .state import FactoryState, SlotRef
from .tasks import NEAR_OUTPUT_SLOTS, Done, Move, TaskPolicy, Wait


#: (m, rad): a destination chosen ahead from where the back-out was to end is taken where it ends this near that
#: pose (the choice compares the legs from there; the chosen leg is planned from where the robot is)
AHEAD_POSE = (0.03, 0.1)
#: (m, rad): and where it ends this near that pose, the leg planned there on the thread is driven as it is (no
#: leg planned again while the robot stands with its part: 0.25-1.2 s in round 1's cycles, ``raf bench planning``)
AHEAD_LEG_POSE = (0.01, 0.05)
#: x dock.timeout: a floor pick still under way this long after it started is given up outright (a failed try),
#: on top of the back-out at dock.timeout that every docking shares: the back-out itself may get nowhere (on the
#: stand-in a floor pick backed into a wall for 280 s before this limit; a pick or a place backs out along its
#: slot's normal to the approach pose its leg arrived on). Not the shared path: picks and places never had this
#: limit (adding it would change them), and :meth:`RoundAgent._timeout` would count it in ``timeouts`` and log
#: it, which it never did. So it stays the floor pick's own.
FLOOR_PICK_GIVE_UP = 2
#: (m, rad): deciding this near where the robot backed out to after its last place, the first legs of an order
#: (tasks.plan_order) are the table's from that slot (else each is planned from the pose: a leg each)
PLACED_POSE = (0.05, 0.3)


@dataclass(frozen=True)
class AgentCommand:
    """What to send this cycle: v (m/s), w (rad/s), the electromagnet."""

    v: float
    w: float
    magnet: bool


@dataclass
class AgentCounters:
    picks: int = 0
    pick_failures: int = 0
    places: int = 0
    place_failures: int = 0
    no_path: int = 0
    escapes: int = 0  # drives to the nearest clear point (the robot too close to something to plan from)
    timeouts: int = 0
    stale_pose_cycles: int = 0
    relocalizations: int = 0  # times it stopped to look at markers (the pose's uncertainty too large)
    relocalize_timeouts: int = 0  # ... and went on after relocalize_timeout without the uncertainty shrinking (with
    # a part on, also once its std stopped falling for recovery.look_patience)
    blocked: int = 0  # legs found stuck or timed out and re-planned around the spot
    parts_lost: int = 0  # the contact switch released while carrying
    replans_off_path: int = 0  # legs planned again because the robot was far off its path
    parts_refound: int = 0  # searches for a lost part in which the LIDAR found it on the floor
    floor_picks: int = 0  # lost parts picked up from the floor again
    choices_ahead: int = 0  # picked parts' destinations chosen while backing out (tasks.choose_ahead)
    legs_ahead: int = 0  # of those, the leg planned on the thread driven as it was (AHEAD_LEG_POSE)
    floor_pick_failures: int = 0  # floor picks that failed (no contact, not held, blocked, no path, timeout)
    parts_left: int = 0  # lost parts left on the floor after recovery.refind_tries failed floor picks


#: The recoveries among the :class:`AgentCounters` that the competition experiment reports per run and sums per
#: round: parts that fell off the magnet and those found and picked up again, stops to look at markers and those
#: that timed out, legs re-planned around a blocked spot or from far off their path.
RECOVERY_COUNTS = ("parts_lost", "parts_refound", "floor_picks", "relocalizations", "relocalize_timeouts", "blocked",
                   "replans_off_path")


def recovery_counts(counters: dict[str, int]) -> dict[str, int]:
    """The :data:`RECOVERY_COUNTS` in ``counters`` (``vars`` of an :class:`AgentCounters`, or the agent's
    ``/diagnostics`` values; an agent that lacked one has none of it)."""
    return {k: int(counters[k]) for k in RECOVERY_COUNTS if k in counters}


@dataclass
class RoundAgent:
    """See the module docstring. ``settings``: every tuning setting (:class:`~.settings.AgentSettings`)."""

    field: object
    robot: object
    settings: AgentSettings = field(default_factory=AgentSettings)  # agent/settings.py: every tuning setting
    limits: DriveLimits | None = None  # None: DriveLimits.from_robot with settings.drive
    events: list = field(default_factory=list)
    counters: AgentCounters = field(default_factory=AgentCounters)

    def __post_init__(self):
        r, f = self.robot, self.field
        self.limits = self.limits or DriveLimits.from_robot(r, **self.settings.drive.given())
        self.dt = float(r.control_period)
        self.policy = TaskPolicy.for_field(f)
        self.delays = DelayEstimator(lanes_of(f))
        self.follower = PathFollower(self.limits, self.dt)
        c = self.settings.carry
        cl = {k: v for k, v in (("w_max", c.w_max), ("alpha_max", c.alpha_max), ("v_max", c.v_max),
                                ("long_spin", c.long_spin), ("w_long_spin", c.w_long_spin),
                                ("spin_settle", c.spin_settle), ("spin_settle_within", c.spin_settle_within))
              if v > 0}
        self.carry_limits = replace(self.limits, **cl)
        ds = self.settings.dock
        dock = DockSettings(v_dock=ds.approach_speed, v_place=ds.place_speed, magnet_early=ds.magnet_early,
                            press_time=ds.press_time, place_gate=ds.place_gate, pick_gate=ds.pick_gate,
                            v_back_carrying=self.settings.carry.back_speed or DockSettings.v_back,
                            a_back_carrying=self.settings.carry.back_accel)
        self.docker = Docker(self.limits, self.dt, float(r.electromagnet["x"]), f.part, dock)
        # the place approach steers with a part on the magnet: no faster turning than carrying allows
        dl = self.docker
        dl.place_limits = replace(dl.place_limits, w_max=min(dl.place_limits.w_max, self.carry_limits.w_max),
                                  alpha_max=min(dl.place_limits.alpha_max, self.carry_limits.alpha_max))
        self.legs = LegPlanner(f, r, self.settings, self.limits, self.carry_limits, self.dt, self.docker.entry_speed)
        # a part dropped on the floor: found and picked up again (modes search, to_floor, floor_pick)
        self.floor = FloorRecovery(f, r, self.settings, self.limits, self.dt, self.legs, dock, self.counters,
                                   self._event, self._obstacles, self._mapped)
        self.ahead = Ahead()  # a picked part's destination, chosen while the robot backs out (_choose_ahead)
        self._ahead_pick = -math.inf
        self.mode = "wait_start"
        self.state: FactoryState | None = None
        self.state_time = -math.inf
        self.need_state_after = 0.0
        self.task: Move | Wait | Done | None = None
        self.carrying: PartType | None = None
        self.target: SlotRef | None = None
        self.attempts = 0
        self.magnet = False
        self.path = None
        self._last_poll = -math.inf
        self.failures: dict[SlotRef, int] = {}  # failed tasks per source slot
        self.place_failed: dict[SlotRef, int] = {}  # failed places per destination slot
        self.gated_in_a_row = 0  # places of the carried part the place gate stopped in a row (dock.place_gate_tries)
        self._mode_t0 = 0.0
        self._budget = math.inf  # s the current leg may take before it is abandoned
        self._released_t: float | None = None  # when the magnet let go of the part being placed
        self._release_pose = None  # ... and where the robot was then
        self._v = self._w = 0.0
        self.t = 0.0
        self.relocalizer = Relocalizer(f, self._can_turn)
        self.stuck = StuckDetector()
        self.blocked_spots: list[tuple[float, float, float]] = []  # (x, y, until t)
        self._resume: str | None = None  # the leg to re-plan after re-localizing
        self._resume_path: dict | None = None  # ... or the path to go on along (PathFollower.suspend)
        self._reloc_quiet_until = -math.inf
        self._reloc_t0 = 0.0
        self._calm = 0  # cycles with the uncertainty back below the limit
        self._calm_below = 0.0  # m: the position std re-localizing waits for
        self._look_best = (math.inf, 0.0)  # (the lowest position std of the look so far, when it was reached)
        self._leg_replans = 0
        self._no_contact = 0
        self._no_path: dict = {}  # consecutive legs without a path per target (SlotRef)
        self._escapes = 0  # escape drives since the last leg that started
        self.scan: Scan | None = None  # the latest LIDAR sweep (on_scan), None: never given one
        self._held_pose = None  # the pose at the last cycle the contact switch showed the carried part
        self._held_state = None  # ... and the factory's state as the agent knew it then
        self.order: Plan | None = None  # the order of the moves last chosen (tasks.plan_order), its first the task
        self._placed: tuple | None = None  # (slot, pose): where the robot stood after its last place

    def prepare(self) -> float:
        """Get what deciding needs before the round starts: with ``tasks.plan_order``, the table of leg times
        (:class:`~.order.LegTimes`; measured once per map, robot and leg settings, about 4 s of CPU, then read from the
        cache file: :func:`~.order.leg_times`). Returns the seconds it took (0: nothing to do)."""
        if not self.settings.tasks.plan_order:
            return 0.0
        t0 = _time.perf_counter()
        self._leg_times()
        return _time.perf_counter() - t0

    @property
    def d_dock(self) -> float:
        """Distance (m) from a slot's centre to base_link docked there (the leg planner's)."""
        return self.legs.d_dock

    @property
    def lost(self) -> LostPart | None:
        """A part that fell off the magnet, being recovered (:attr:`.FloorRecovery.lost`), or None."""
        return self.floor.lost

    @property
    def floor_parts(self) -> list[PartObstacle]:
        """Lost parts left on the floor (:attr:`.FloorRecovery.left`): obstacles while carrying."""
        return self.floor.left

    # ------------------------------------------------------------------------------------------ inputs
    @property
    def activity(self) -> str:
        """What the robot is doing this cycle, for the time split (docs/agent.md): ``wait_start``,
        ``decide`` (deciding or waiting for a machine), ``drive`` (moving along a path, turning on the way
        included), ``turn`` (turning in place on a path), ``final_turn``, ``dock_approach``, ``dock_wait``
        (magnet on/off, standing), ``dock_back`` (backing out), ``relocalize`` (standing, looking at markers),
        ``search`` (looking for a part that fell off the magnet), ``done``."""
        if self.mode in ("wait_start", "decide", "done", "relocalize", "search"):
            return self.mode
        if self.mode == "escape":
            return "drive"
        if self.mode in ("to_pick", "to_place", "to_floor"):
            ph = self.follower.phase
            return "drive" if ph in ("drive", "done") else ph
        ph = self._docking().phase
        return {"approach": "dock_approach", "press": "dock_approach", "grip": "dock_wait", "release": "dock_wait",
                "back": "dock_back"}.get(ph, "dock_back")

    @property
    def wants_state(self) -> bool:
        """True when the caller should poll the server now and call :meth:`on_state`."""
        if self.mode == "done":
            return False
        # also while driving: the delay estimate is only as sharp as the polls are frequent
        return self.state_time <= self.need_state_after or self.t - self._last_poll >= self.settings.tasks.state_period

    def on_state(self, state: FactoryState, t: float) -> None:
        """A fresh server state seen at time ``t`` (s)."""
        self._last_poll = t
        if (self.state is not None and self.mode == "decide" and self.task is not None
                and not self.state.same_slots(state)):
            self._event(t, f"server state changed: {state}")
        self.state, self.state_time = state, t
        seen = self.delays.update(state, t)
        if seen is not None:
            self._event(t, f"processing delay observed: {seen:.1f} s (estimate {self.delays.estimate:.1f} s)")
        if self.mode == "wait_start":
            self._event(t, f"part list {state.letters('incoming')}: the run starts")
            self.mode = "decide"

    def on_scan(self, scan: Scan) -> None:
        """A LIDAR sweep (:class:`~.refind.Scan`), optional: hand over each one as it comes. Only a part that fell
        off the magnet is looked for in it (the newest one taken while the robot stood still)."""
        self.scan = scan

    # ------------------------------------------------------------------------------------------ cycle
    def step(self, t: float, pose, contact: bool, uncertainty=None) -> AgentCommand:
        """One control cycle: ``t`` (s), the pose estimate (x, y, theta) or None when stale, the contact
        switch, and optionally the pose's uncertainty (:func:`~.recovery.uncertainty_of`: a position std
        in m, (position m, heading rad), or a 3x3 / 6x6 covariance). Returns what to send."""
        self.t = float(t)
        if pose is None:  # stale estimate: brake and wait (the caller decides what is stale)
            self.counters.stale_pose_cycles += 1
            return self._brake()
        if self.mode in ("wait_start", "done"):
            return self._brake()
        unc = uncertainty_of(uncertainty)
        rc = self.settings.recovery
        uncertain = unc is not None and (unc[0] > rc.uncertainty_limit or unc[1] > rc.heading_uncertainty_limit)
        if self.mode == "relocalize":
            return self._relocalize(pose, unc)
        if uncertain and self.mode in ("to_pick", "to_place") and self.t >= self._reloc_quiet_until:
            self._start_relocalize(pose, f"pose uncertain ({unc[0] * 1000:.0f} mm, {unc[1]:.2f} rad): stopping to "
                                         "look at markers", 0.6 * rc.uncertainty_limit)
            return self._brake()
        if self.mode == "to_place" and self.carrying is not None:
            # the contact switch stays pressed while a part hangs on the magnet
            self._no_contact = 0 if contact else self._no_contact + 1
            if contact:
                self._held_pose, self._held_state = tuple(pose[:3]), self.state
            if self._no_contact >= self.settings.recovery.lost_cycles:
                self._part_lost()
                return self._brake()
        if self.mode == "search":
            return self._search_step(pose)
        if self.mode == "decide":
            if self.state_time <= self.need_state_after:  # (a state polled in the cycle it was asked for came before)
                return self._brake()
            self._decide(pose)
            if self.mode == "decide" or self.mode == "done":
                return self._brake()
        if self.mode == "escape":  # (:meth:`_no_leg`) then decide again from where it got to
            o = self.follower.step(pose)
            if o.done or o.off_path or self.t - self._mode_t0 > self.settings.recovery.escape_time:
                self.follower.stop()
                if self.lost is not None and self.lost.where is not None and self.carrying is None:
                    self._go("to_floor", pose)  # on to the part on the floor from here
                else:
                    self.mode, self.need_state_after = "decide", self.t
                return self._brake()
            return self._cmd(o.v, o.w)
        if self.mode in ("to_pick", "to_place", "to_floor") and self.t - self._mode_t0 > self._budget:
            if self._leg_replans < self.settings.recovery.replans:
                self._blocked(pose, f"took more than {self._budget:.0f} s")
            else:
                self._timeout(f"{self.mode.replace('_', ' ')} {self.target} took more than {self._budget:.0f} s")
            return self._brake()
        if self.mode in ("pick", "place", "floor_pick") and self.t - self._mode_t0 > self.settings.dock.timeout \
                and self._docking().phase not in ("back", "done", "failed"):
            self._docking().abort(pose)  # back out first, then the failure comes through the docker
        if self.mode in ("to_pick", "to_place", "to_floor"):
            if self.stuck.update(self.t, pose, self._v, self._w):
                if self._leg_replans < self.settings.recovery.replans:
                    self._blocked(pose, "stuck")
                else:
                    self._timeout(f"{self.mode.replace('_', ' ')} {self.target}: stuck after "
                                  f"{self.settings.recovery.replans} re-plans")
                return self._brake()
            o = self.follower.step(pose)
            if self._unsure_before_place(o, unc):
                self._start_relocalize(pose, f"pose unsure before the place ({unc[0] * 1000:.0f} mm): stopping to "
                                             "look at markers",
                                       0.6 * self.settings.recovery.place_uncertainty_limit,
                                       go_on=self.settings.recovery.go_on_after_look)
                return self._brake()
            if o.off_path:  # far off the path (a slip, a push): plan again from here
                self._event(self.t, f"{o.off_path * 100:.0f} cm off the path: re-planning")
                self.counters.replans_off_path += 1
                self._go(self.mode, pose)
                return self._brake()
            if o.done:
                self._start_dock(pose)
            return self._cmd(o.v, o.w)
        if self.mode == "floor_pick" and self.t - self._mode_t0 > FLOOR_PICK_GIVE_UP * self.settings.dock.timeout:
            self._floor_failed("timeout", pose)  # not even backing out gets anywhere
            return self._brake()
        if self.mode in ("pick", "place", "floor_pick"):
            o = self._docking().step(pose, contact)
            self.magnet = o.magnet
            if self.mode == "pick" and o.phase == "grip" and self._ahead_pick != self._mode_t0:
                self._ahead_pick = self._mode_t0  # once a pick (its start)
                self._choose_ahead()
            if self.mode == "place" and not o.magnet and self._released_t is None:
                self._released_t = self.t  # the part is free from now: the delay is measured from here
                self._release_pose = tuple(pose[:3])
            if o.failed:
                self._dock_failed(o.failed, pose)
            elif o.done:
                self._dock_done(pose)
            return self._cmd(o.v, o.w)
        return self._brake()

    # ------------------------------------------------------------------------------------------ decisions
    def _decide(self, pose) -> None:
        st = self.state
        if self.floor.pick_lost is not None:  # a state seen since a pick let its part go: is it still in its slot?
            if self.floor.let_go_missing(self.t, self.task, st):
                self._start_search()
                return
        if self.floor.place_lost is not None:  # the first state since a place: is the part in its slot?
            if self.floor.place_missing(self.t, st):
                self._start_search()
                return
        if self.carrying is not None:  # a place failed or the destination changed: find a new one
            dest = self._usable(self.policy.destinations(st, self.carrying))
            if not dest:
                return  # hold the part until a destination is free (re-polled every state_period)
            self.target = dest[0]
            self._leg_replans = 0
            self._go_fastest("to_place", pose, dest)
            return
        ready = {ln.input: self.delays.expected_ready(ln.input) for ln in self.delays.lanes}
        avoid = {ref for ref, n in self.failures.items() if n >= self.settings.tasks.give_up_after}
        task = self.policy.next_task(st, robot_xy=tuple(pose[:2]), ready_at={k: v for k, v in ready.items() if v},
                                     avoid=avoid)
        leg = None
        self.order = None
        if isinstance(task, Move) and self.settings.tasks.plan_order:
            task = self._ordered(pose, st, avoid, task)
        elif isinstance(task, Move) and self.settings.tasks.pick_by_time:
            task, leg = self._soonest(pose, self.policy.tied(st, avoid), task)
        if task != self.task:
            self._event(self.t, f"task: {task}")
        self.task = task
        if isinstance(task, Done):
            self.mode = "done"
            return
        if isinstance(task, Wait):
            return  # stay, poll again
        self.target = task.source
        self.attempts = 0
        self._leg_replans = 0
        if leg is not None:
            self._start_planned("to_pick", leg)
            return
        self._go("to_pick", pose)

    def _soonest(self, pose, tied: list, default: Move) -> tuple[Move, LegPlan | None]:
        """Of the tied moves (:meth:`TaskPolicy.tied`), the one whose pick leg from ``pose`` plus its carrying
        leg from the part's slot to its destination take the least time (:meth:`.LegPlanner.leg_time`, a
        kinematic run of the follower on each planned leg), with its planned pick leg; ``default`` (and no leg)
        when only one is tied or none has a path."""
        if len(tied) < 2:
            return default, None
        obstacles = self._obstacles()
        best = None
        for m in tied:  # timed by the planner's legs; the chosen pick leg through a grid point if that is faster
            try:
                leg, t_leg = self.legs.timed(obstacles, pose, m.source, False, "pick")
                cost = t_leg + self._carry_time(m)
            except NoPath:
                continue
            if best is None or cost < best[0] - 1e-6:
                best = (cost, m, leg, t_leg)
        if best is None:
            return default, None
        return best[1], self.legs.faster(obstacles, pose, best[2], False, "pick", best[3])[0]

    def _ordered(self, pose, st: FactoryState, avoid: set, rules: Move) -> Move:
        """``tasks.plan_order``: the first move of the order of the moves left that places the last part soonest
        (:func:`~.order.plan_order`), unless the best order starting with the rules' part ``rules`` ends less than
        ``tasks.plan_margin`` s later: then that one's (the rules' part, to the slot that order gives it). The order
        is kept in :attr:`order`; ``rules`` when there is none."""
        times = self._leg_times()
        near = ()
        if self.settings.tasks.reserve_outgoing:  # every outgoing slot, nearest the outputs first
            near = tuple(self.policy.outgoing_by_nearness())
        placed_at = {ln.input: self.delays.placed_at(ln.input) for ln in self.policy.lanes}
        kw = dict(first_leg=self._first_legs(pose, st, avoid), delay=self.delays.estimate,
                  placed_at={k: v for k, v in placed_at.items() if v is not None}, avoid=avoid, near_outputs=near)
        free = plan_order(self.policy, st, self.t, times, **kw)
        if free is not None and free.complete and free.moves[0].source == rules.source:
            kept = free  # an exact search that starts with the rules' part: the second search would end as soon
        else:
            kept = plan_order(self.policy, st, self.t, times, first=rules.source, **kw)
        if free is not None and (kept is None or free.finish < kept.finish - self.settings.tasks.plan_margin):
            self.order = free
        else:
            self.order = kept
        if self.order is None:
            return rules
        first = self.order.moves[0]
        if first != rules:
            why = ""
            if first.source != rules.source and kept is not None:
                why = f" (the rules' part: {kept.finish - self.t:.1f} s)"
            self._event(self.t, f"ordered: {len(self.order.moves)} moves, the last placed in "
                                f"{self.order.finish - self.t:.1f} s{why}")
        return first

    def _first_legs(self, pose, st: FactoryState, avoid: set) -> dict[SlotRef, float]:
        """Seconds of the pick leg from ``pose`` to each part that may move now: the table's row of the slot the
        robot last placed in when it stands where it backed out to from there (``PLACED_POSE``), else each leg
        planned from ``pose`` (:meth:`.LegPlanner.timed`; no path: left out)."""
        times = self._leg_times()
        placed = self._placed
        row = placed is not None and _near(pose, placed[1], PLACED_POSE)
        out, obstacles = {}, None
        for m in self.policy.candidates(st, avoid):
            if row and (placed[0], m.source) in times.empty:
                out[m.source] = times.empty[(placed[0], m.source)]
                continue
            obstacles = obstacles if obstacles is not None else self._obstacles(state=st)
            try:
                out[m.source] = self.legs.timed(obstacles, pose, m.source, False, "pick")[1]
            except NoPath:
                continue
        return out

    def _leg_times(self) -> LegTimes:
        """The table of leg times between the slots parts are picked from (incoming, machine outputs) and placed
        in (outgoing, machine inputs), on the map with no part in it (:meth:`.LegPlanner.between`): from this
        process's memory or the cache file, keyed by everything a leg depends on (:func:`~.order.table_key`)."""
        return leg_times(self._table_key(), self.measure_leg_times)

    def measure_leg_times(self) -> LegTimes:
        """Measure the table of :meth:`_leg_times` (no cache): 128 legs planned and timed, about 4 s of CPU
        (``raf bench planning``)."""
        outputs = [ln.output for ln in self.policy.lanes]
        inputs = [ln.input for ln in self.policy.lanes]
        picks = [SlotRef("incoming", n) for n in range(1, 5)] + outputs
        places = [SlotRef("outgoing", n) for n in range(1, 5)] + inputs
        obstacles = FieldObstacles(self.field, [])
        return LegTimes.measure(picks, places, lambda a, b, c: self.legs.between(obstacles, a, b, c))

    def _table_key(self) -> str:
        """The leg-time table's key: the map, the robot and the settings a leg depends on (not, say, the server's
        port: a test or a run with other such settings reads the same table)."""
        s = self.settings
        return table_key(self.field, self.robot, s.legs, s.carry, s.drive, s.dock, self.limits, self.carry_limits,
                         self.dt)

    def _planned(self, dest: list) -> list:
        """``dest`` cut to the slot the order gave the part being moved (:meth:`_ordered`), when it is one of
        them."""
        o = self.order
        if o is not None and o.moves and o.moves[0] == self.task and self.task.target in dest:
            return [self.task.target]
        return dest

    def _carry_time(self, m: Move) -> float:
        """Seconds of the carrying leg of ``m``: from the carrying approach pose at its source (where the robot
        backs out to) to its target. Raises NoPath."""
        obstacles = self.legs.obstacles(self.state.with_slot(m.source, None), self.blocked_spots)
        slot = self.field.slot(m.source.zone, m.source.number)
        fp = self.legs.footprint(True)
        start = self.legs.path_planner(obstacles, True).approach_pose(slot, self.d_dock, fp)
        return self.legs.leg_time(self.legs.plan(obstacles, start, m.target, True, "place", via=False), start, True)

    def _usable(self, dest: list) -> list:
        """Destinations without ``give_up_after`` - 1 failed places; once every one has failed so often, those
        that failed least (a slot is better than none, and the tries go round the slots instead of repeating the
        one nearest: a place failing the same way at once from where it stands was tried 869 times in a row at one
        slot, stop 47)."""
        fails = {d: self.place_failed.get(d, 0) for d in dest}
        ok = [d for d in dest if fails[d] < self.settings.tasks.give_up_after - 1]
        return ok or [d for d in dest if fails[d] == min(fails.values(), default=0)]

    def _obstacles(self, exclude: SlotRef | None = None, state: FactoryState | None = None,
                   carrying: bool | None = None) -> FieldObstacles:
        """The field as legs are planned on now: the parts of ``state`` (default the last state; but the one in
        ``exclude``), the blocked spots still remembered (those past their time are forgotten here) and the
        parts lying on the floor (as seen carrying a part or not; default: whether the robot carries one)."""
        blocked, floor = self._place_inputs(self.carrying is not None if carrying is None else carrying)
        self.blocked_spots = list(blocked)
        return self.legs.obstacles(self.state if state is None else state, list(blocked), exclude, list(floor))

    def _place_inputs(self, carrying: bool) -> tuple[tuple, tuple]:
        """What legs are planned on besides the state: the blocked spots not past their time and the parts lying
        on the floor (as seen carrying a part or not)."""
        return tuple(b for b in self.blocked_spots if b[2] > self.t), tuple(self.floor.obstacles(carrying))

    def _by_time(self, dest: list, carrying: bool) -> bool:
        """The destination of ``dest`` is chosen by time (:meth:`_fastest`): ``tasks.choose_by_time`` on, a
        choice to make, and not carrying on arcs (``carry.arcs`` plans its own leg)."""
        least = 1 if self.settings.tasks.plan_order else 2  # one: the order's, its leg planned while backing out
        return (self.settings.tasks.choose_by_time and len(dest) >= least
                and not (carrying and self.settings.carry.arcs))

    def _mapped(self, floor: list[PartObstacle]) -> FieldObstacles:
        """The last state's parts, the blocked spots as remembered (:meth:`_obstacles` forgets those past their
        time) and ``floor``, parts lying on the floor (the floor recovery's checks of a turn and a straight line)."""
        return self.legs.obstacles(self.state, self.blocked_spots, None, floor)

    def _can_turn(self, pose) -> bool:
        """The exact outline (carrying or not, 5 mm margin) at ``pose`` touches nothing."""
        fp = self.legs.footprint(self.carrying is not None)
        if getattr(self, "_turn_obstacles", None) is None or self._turn_obstacles[0] != self.state_time:
            self._turn_obstacles = (self.state_time, self._obstacles() if self.state is not None else
                                    FieldObstacles(self.field, []))
        return not self._turn_obstacles[1].collides(fp.inflated(0.005), pose)

    def _start_relocalize(self, pose, why: str, calm_below: float, go_on: bool = False) -> None:
        """Stop the leg under way and look at markers (:meth:`_relocalize`) until the position std is at most
        ``calm_below`` m (and the heading's 60 % of its limit). ``go_on``: then go on along the leg's path from
        where the robot stopped (carrying, it does not turn while it looks), else re-plan the leg from there. The
        look before a place stops a few cm before the leg's end, often still on its last curve: a leg planned
        again from there turned on the spot and began the place 15 deg off the slot's normal (stand-in and whole
        stack, round 1: ``off_line``, tests/test_agent_place_look_sim.py)."""
        self.counters.relocalizations += 1
        self._event(self.t, why)
        self._resume, self.mode = self.mode, "relocalize"
        self._reloc_t0, self._calm, self._calm_below = self.t, 0, calm_below
        self._look_best = (math.inf, self.t)
        if go_on and self.carrying is not None:
            self._resume_path = self.follower.suspend()
        else:
            self._resume_path = None
            self.follower.stop()
        self.relocalizer.start(pose)

    def _unsure_before_place(self, o, unc) -> bool:
        """On the last ``PLACE_LOOK`` m of a leg to a place, the pose estimate less sure than
        ``recovery.place_uncertainty_limit`` (position std; not again within a relocalize_timeout of a look that
        timed out). On the real SimTwo the one place in 76 that began with a std above 4.3 mm (18.6 mm) began 36 mm
        off by the truth and dropped its part beside the slot; on the stand-in's whole stack at most 2.2 mm in
        363."""
        lim = self.settings.recovery.place_uncertainty_limit
        return (lim > 0 and self.mode == "to_place" and unc is not None and unc[0] > lim
                and o.remaining < PLACE_LOOK and self.t >= self._reloc_quiet_until)

    def _relocalize(self, pose, unc) -> AgentCommand:
        """Standing still, turn towards markers until the uncertainty is back below the target (60 % of the
        limits, or of ``place_uncertainty_limit`` before a place) for 5 cycles, or relocalize_timeout; then re-plan
        the interrupted leg from here, or go on along its path (the look before a place, :meth:`_start_relocalize`).
        With a part on the magnet it does not turn."""
        rc = self.settings.recovery
        calm = unc is None or (unc[0] <= self._calm_below and unc[1] <= 0.6 * rc.heading_uncertainty_limit)
        self._calm = self._calm + 1 if calm else 0
        sure = self._calm >= 5  # (before the time limits: a look that ends sure is not counted as gone on)
        timed_out = not sure and self.t - self._reloc_t0 > rc.relocalize_timeout
        stalled = not (sure or timed_out) and self._look_stalled(unc)
        if sure or timed_out or stalled:
            if sure:
                self._event(self.t, f"pose certain again after {self.t - self._reloc_t0:.1f} s")
            else:  # go on driving (new views of markers) for as long before looking again
                self._reloc_quiet_until = self.t + rc.relocalize_timeout
                self.counters.relocalize_timeouts += 1
                why = (f"re-localizing took more than {rc.relocalize_timeout:.0f} s" if timed_out else
                       f"the pose's std stopped falling with the part on ({unc[0] * 1000:.0f} mm for "
                       f"{self.t - self._look_best[1]:.1f} s)")
                self._event(self.t, f"{why}: going on")
            mode, self._resume = self._resume or "decide", None
            held, self._resume_path = self._resume_path, None
            if held is not None and mode == "to_place" and self.carrying is not None:
                self.follower.resume(held, (self._v, self._w))  # on along the same path (the look's stop)
                self.mode = mode
                self._mode_t0 += self.t - self._reloc_t0  # the leg's time budget: the look does not count
                self.stuck.reset()
                self._no_contact = 0
            elif mode in ("to_pick", "to_place"):
                self._go(mode, pose)
            else:
                self.mode, self.need_state_after = "decide", self.t
            return self._brake()
        if abs(self._v) > 1e-9:  # stop first
            return self._brake()
        w = self.relocalizer.step(pose, self.dt) if self.carrying is None else 0.0  # no spin with a part on
        return self._cmd(0.0, ramp(self._w, w, self.limits.alpha_max * self.dt))

    def _look_stalled(self, unc) -> bool:
        """Looking with a part on (standing, not turning): the position std has not fallen below 95 % of the
        lowest it reached for ``recovery.look_patience`` s. The view does not change, so no fix is coming: on the
        real SimTwo a look with a part on stood out its 12 s without one (stop 56)."""
        patience = self.settings.recovery.look_patience
        if patience <= 0 or self.carrying is None or unc is None:
            return False
        if unc[0] < 0.95 * self._look_best[0]:
            self._look_best = (unc[0], self.t)
        return self.t - self._look_best[1] > patience

    def _blocked(self, pose, why: str) -> None:
        """Something the map lacks blocks the leg: remember the spot ahead of the robot as an obstacle for
        block_memory s and re-plan the leg around it (at most ``replans`` times per leg)."""
        self._leg_replans += 1
        self.counters.blocked += 1
        fp = self.legs.footprint(self.carrying is not None)
        ahead = (fp.front + 0.03) if self._v >= 0 else (fp.back - 0.03)
        x = pose[0] + ahead * math.cos(pose[2])
        y = pose[1] + ahead * math.sin(pose[2])
        self.blocked_spots.append((x, y, self.t + self.settings.recovery.block_memory))
        self._event(self.t, f"blocked ({why}) near ({x:.2f}, {y:.2f}): re-planning around it")
        self.follower.stop()
        self._go(self.mode, pose)

    def _part_lost(self) -> None:
        self.counters.parts_lost += 1
        self._event(self.t, f"lost the {self.carrying.label} part on the way to {self.target}")
        part, self.carrying = self.carrying, None
        self.magnet = False
        self._no_contact = 0
        self.follower.stop()
        self.mode, self.need_state_after = "decide", self.t
        if self.settings.recovery.refind and self._held_pose is not None:
            # the state as the agent knew it while the part was still held: one polled between the fall and the
            # noticing may already list it in the slot it landed in
            self.floor.fell(self.t, part, self._held_pose, self.target, self._held_state or self.state)
            self._start_search()

    # ------------------------------------------------------------------------------------------ a part on the floor
    def _start_search(self) -> None:
        """Stop, then look for the lost part (mode ``search``, :meth:`_search_step`); a fresh server state is asked
        for (did it land in a slot?)."""
        self.follower.stop()
        self.mode, self.need_state_after = "search", self.t
        self.floor.start_search()

    def _search_step(self, pose) -> AgentCommand:
        """One cycle of the search (:meth:`.FloorRecovery.look`): braking or standing, a turn on the spot, or its
        outcome carried out (:meth:`_floor_next`)."""
        out = self.floor.look(self.t, pose, self._v, self._w, self.scan, self.state, self.state_time)
        if isinstance(out, Next):
            self._floor_next(out, pose)
            return self._brake()
        return self._brake() if out is None else self._cmd(0.0, out)

    def _floor_next(self, nxt: Next, pose) -> None:
        """Do what the floor recovery answered (:class:`.floor.Next`) in the state machine's modes."""
        if nxt.to == "search":
            self._start_search()
        elif nxt.to == "decide":
            self.mode, self.need_state_after = "decide", self.t
        elif nxt.to == "to_floor":
            self._leg_replans = 0
            self._go("to_floor", pose)
        elif nxt.to == "failed":
            self._floor_failed(nxt.reason, pose)
        elif nxt.to == "leg":
            self._start_planned("to_floor", nxt.leg)
        elif nxt.to == "escape":
            self._escapes += 1
            self.follower.limits = self.limits
            self._escape(pose, nxt.point, no_spin=True)
        else:  # no_path
            self._no_leg(pose)

    def _go_floor(self, pose) -> None:
        """Plan the leg to the lost part on the floor and start it (:meth:`.FloorRecovery.plan`); standing too close
        to it to turn, first drive straight away from it (up to ``escape_tries`` times); no leg: :meth:`_no_leg`."""
        self._floor_next(self.floor.plan(self.t, pose, self._escapes < self.settings.recovery.escape_tries), pose)

    def _floor_picked(self, pose) -> None:
        """Picked up from the floor: on as after any pick, to a destination."""
        lost = self.floor.picked(self.t)
        self.carrying = lost.part
        self.gated_in_a_row = 0
        self.docker.held_offset = self.floor.docker.held_offset  # the place repeats the offset it was held with
        self._held_pose, self._held_state = tuple(pose[:3]), self.state
        dest = self._usable(self.policy.destinations(self.state, self.carrying))
        if not dest:
            self.mode, self.need_state_after = "decide", self.t
            return
        self.target = lost.dest if lost.dest in dest else dest[0]
        self._leg_replans = 0
        self._go_fastest("to_place", pose, dest)

    def _floor_failed(self, reason: str, pose) -> None:
        """A floor pick (or the leg to it, or a search) failed (:meth:`.FloorRecovery.failed`): look again, or the
        part is left where it lies and the round goes on."""
        self.magnet = False
        self.follower.stop()
        self._floor_next(self.floor.failed(self.t, reason), pose)

    def _go(self, mode: str, pose, obstacles: FieldObstacles | None = None) -> None:
        """Plan the leg to ``self.target`` from ``pose`` and start it in ``mode`` (``to_pick`` / ``to_place``);
        no path: :meth:`_no_leg`. ``to_floor``: the lost part on the floor (:meth:`_go_floor`). ``obstacles``:
        the field as it is now, if already made (its remembered searches are reused)."""
        if mode == "to_floor":
            self._go_floor(pose)
            return
        carrying = self.carrying is not None
        self.follower.limits = self.limits if not carrying else self.carry_limits
        obstacles = obstacles if obstacles is not None else self._obstacles()
        if carrying and self.settings.carry.arcs and self._go_on_arcs(mode, pose, obstacles):
            return
        try:
            leg = self.legs.plan(obstacles, pose, self.target, carrying, _dock_of(mode))
        except NoPath as e:
            self.counters.no_path += 1
            self._event(self.t, f"no path to {self.target}: {e}")
            self._no_leg(pose)
            return
        self._start_planned(mode, leg)

    def _start_planned(self, mode: str, leg: LegPlan) -> None:
        """Start ``leg``, just planned with a path, in ``mode``: the target's count of legs without a path and the
        escape drives (:meth:`_no_leg`) start again. A leg to the lost part on the floor (``to_floor``) is not to
        ``self.target`` (it still names the slot of the task the part fell in): that count is left alone."""
        if mode != "to_floor":
            self._no_path.pop(self.target, None)
        self._escapes = 0
        self._start_leg(mode, leg)

    def _no_leg(self, pose) -> None:
        """No path to the target: never a loop of asking again. Where the robot stands too close to
        something for its outline (pushed into a corner, a slip), it first drives to the nearest clear point
        (up to ``escape_tries`` times); a target without a path ``give_up_after`` times running is given up
        (its part left alone, or, carrying, another destination preferred), as a failed pick or place is."""
        carrying = self.carrying is not None
        escape = self.legs.escape_point(self._obstacles(), pose, carrying)
        tries = self.settings.recovery.escape_tries
        if escape is not None and self._escapes < tries:
            self._escapes += 1
            self.counters.escapes += 1
            point = escape.xy
            # carrying, the drive steers and never turns on the spot: a point beside the robot it barely nears
            # (whole stack, round 3: it stood still for 170 s after its escapes). The last try may turn there.
            spin = carrying and not escape.straight and self._escapes == tries
            self._event(self.t, f"too close to an obstacle at ({pose[0]:.2f}, {pose[1]:.2f}): driving to "
                                f"({point[0]:.2f}, {point[1]:.2f}) first" + (", turning on the spot" if spin else ""))
            self._escape(pose, point, no_spin=carrying and not spin)
            return
        if self.lost is not None and not carrying:  # on the way to a part on the floor
            self._floor_failed("no path", pose)
            return
        n = self._no_path[self.target] = self._no_path.get(self.target, 0) + 1
        if n >= self.settings.tasks.give_up_after:
            self._no_path.pop(self.target, None)
            self._event(self.t, f"no path to {self.target} {n} times: giving it up")
            # the next target starts a new round of escape drives: a robot whose escapes ended short of clear
            # space (an escape ends after escape_time or off its path) does not stand still for the round
            self._escapes = 0
            if carrying:
                self.place_failed[self.target] = max(self.place_failed.get(self.target, 0),
                                                     self.settings.tasks.give_up_after)
            elif isinstance(self.task, Move):
                self.failures[self.task.source] = max(self.failures.get(self.task.source, 0),
                                                      self.settings.tasks.give_up_after)
        self.mode, self.need_state_after = "decide", self.t + self.settings.tasks.state_period

    def _escape(self, pose, point: tuple[float, float], no_spin: bool) -> None:
        """Drive straight to ``point`` (mode ``escape``), backwards when it lies behind; then decide again from
        there, or go on to the part on the floor."""
        behind = (point[0] - pose[0]) * math.cos(pose[2]) + (point[1] - pose[1]) * math.sin(pose[2]) < 0
        self._follow([tuple(pose[:2]), point], final_heading=None, reverse=behind, no_spin=no_spin)
        self.mode, self._mode_t0 = "escape", self.t

    def _go_fastest(self, mode: str, pose, dest: list) -> None:
        """Start the leg to the destination of ``dest`` (best first) that takes the least time
        (:meth:`_fastest`); with ``choose_by_time`` off, to ``self.target`` (or ``dest[0]``)."""
        if not self._by_time(dest, self.carrying is not None):
            if self.target not in dest:
                self.target = dest[0]
            self._go(mode, pose)
            return
        target, leg = self._fastest(mode, pose, dest, self.state, self.carrying, self.task, self._obstacles())
        self.target = target
        if leg is None:  # no path to any: the usual failure handling
            self._go(mode, pose)
            return
        self._start_leg(mode, leg)

    def _choose_ahead(self) -> None:
        """Gripping a part: start choosing its destination (:meth:`_fastest`) on a thread (:class:`.Ahead`),
        from the pose where the back-out will end and the inputs the choice after it would have
        (:meth:`_dock_done` takes it when those are still the inputs: :meth:`_ahead_still`)."""
        if not (self.settings.tasks.choose_ahead and isinstance(self.task, Move)):
            return
        task, part = self.task, self.task.part
        state = self.state.with_slot(task.source, None)
        dest = self._planned(self._usable(self.policy.destinations(state, part)))
        if not self._by_time(dest, True):
            return
        obstacles = self._obstacles(state=state, carrying=True)
        pose = self.docker.retreat_pose()
        key = (pose, tuple(dest), state, *self._place_inputs(True))
        self.ahead.start(key, lambda: (*self._fastest("to_place", pose, dest, state, part, task, obstacles),
                                       obstacles, pose))

    def _ahead_still(self, key, pose, dest: list) -> bool:
        """The choice started ahead (``key``: the pose it was made from, the destinations, the state, the blocked
        spots and the parts on the floor) holds for ``pose`` and ``dest`` now: within ``AHEAD_POSE`` of that pose
        and the same inputs."""
        at, was_dest, state, blocked, floor = key
        return (_near(pose, at, AHEAD_POSE) and was_dest == tuple(dest) and state.same_slots(self.state)
                and (blocked, floor) == self._place_inputs(True))

    def _fastest(self, mode: str, pose, dest: list, state: FactoryState, carrying: PartType | None, task,
                 obstacles: FieldObstacles) -> tuple[SlotRef, LegPlan | None]:
        """The destination of ``dest`` (best first) whose leg from ``pose`` takes the least time among those of
        the best rank (:meth:`TaskPolicy.destination_class` in ``state``; every outgoing slot is of one rank), by
        :meth:`.LegPlanner.leg_time` of the planner's legs, then the ``VIA_RANKED`` fastest through a grid point
        where that is faster (:meth:`.LegPlanner.faster`, ``legs.via_grid``), and its leg (None: no path to
        any, ``dest[0]``). Reads only its arguments and the agent's settings: :class:`~.ahead.Ahead` runs it on
        a thread while the robot backs out with the part (:meth:`_choose_ahead`)."""
        if self.settings.tasks.reserve_outgoing and carrying is PartType.BLUE and isinstance(task, Move):
            if self.policy.is_output(task.source):  # the slots it reaches turning one way only
                near = self.policy.outgoing_near_outputs(state)[:NEAR_OUTPUT_SLOTS]
                dest = [d for d in dest if d in near] or dest
            else:  # leave those to the parts still to come out of the machines
                keep = set(self.policy.reserved_outgoing(state, task.source))
                dest = [d for d in dest if d not in keep] or dest
        best_class = min(self.policy.destination_class(state, d) for d in dest)
        timed = []
        for d in dest:  # timed by the planner's legs
            if self.policy.destination_class(state, d) != best_class:
                continue
            try:
                leg, seconds = self.legs.timed(obstacles, pose, d, carrying is not None, _dock_of(mode))
            except NoPath:
                continue
            timed.append((seconds, d, leg))
        if not timed:
            return dest[0], None
        best = timed[0]
        for c in timed[1:]:
            if c[0] < best[0] - 1e-6:
                best = c
        # the fastest few through a grid point, where that is faster (legs.via_grid; a search costs several legs)
        for cost, d, leg in sorted(timed, key=lambda c: c[0])[:VIA_RANKED]:
            leg, cost = self.legs.faster(obstacles, pose, leg, carrying is not None, _dock_of(mode), cost)
            if cost < best[0] - 1e-6:
                best = (cost, d, leg)
        return best[1], best[2]

    def _start_leg(self, mode: str, leg: LegPlan) -> None:
        """Drive the planned leg ``leg`` in ``mode``, with a time budget."""
        path = leg.path
        self.path = path
        self.follower.limits = self.limits if self.carrying is None else self.carry_limits
        if self.settings.legs.smooth:
            self._follow(leg.smooth, final_heading=None if leg.end_speed > 0 else leg.goal[2],
                         end_speed=leg.end_speed)
        else:
            self._follow(leg.smooth, final_heading=leg.goal[2])
        self.mode = mode
        self._mode_t0 = self.t
        self.stuck.reset()
        self._no_contact = 0
        lim = self.limits  # generous: three times the straight-line time, plus every turn and 10 s
        self._budget = 10.0 + 3.0 * path.length / lim.v_max + len(path.points) * math.pi / lim.w_max * 2

    def _go_on_arcs(self, mode: str, pose, obstacles: FieldObstacles) -> bool:
        """Start the place leg on arcs only (:meth:`.LegPlanner.plan_on_arcs`), never turning on the spot, at
        gentle lateral accelerations. False when there is no such leg (the caller plans the usual one)."""
        try:
            leg = self.legs.plan_on_arcs(obstacles, pose, self.target)
        except NoPath:
            return False
        except NoCarryPath as err:
            self._event(self.t, f"{err}: turning on the spot instead")
            return False
        sp = leg.smooth
        self.path = leg.path
        self.follower.limits = replace(self.limits, a_lat=self.settings.carry.a_lat)  # gentle arcs: the part slides
        self._follow(sp, final_heading=None, end_speed=leg.end_speed, no_spin=True)
        self.mode = mode
        self._mode_t0 = self.t
        self.stuck.reset()
        self._no_contact = 0
        self._budget = 10.0 + 3.0 * sp.length / self.limits.v_max + 2.0 * len(sp.pieces)
        return True

    def _start_dock(self, pose) -> None:
        v0 = self.follower.v
        self.follower.v = self.follower.w = 0.0  # the docker drives from here (at the speed it arrived with)
        if self.mode == "to_floor":
            self.floor.start_dock(self.t, pose, v0)
            self.mode, self._mode_t0 = "floor_pick", self.t
            return
        slot = self.field.slot(self.target.zone, self.target.number)
        if self.mode == "to_pick":
            retreat = self.legs.retreat(self._obstacles(exclude=self.target), self.target, carrying=True)
            self.docker.start_pick(slot, pose, retreat, v0=v0)
            self._event(self.t, f"docking to pick the {self.task.part.label} part at {self.target}")
            self.mode = "pick"
            self._mode_t0 = self.t
        else:
            retreat = self.legs.retreat(self._obstacles(exclude=self.target), self.target, carrying=False)
            tries = self.settings.dock.place_gate_tries
            gate = not (tries and self.gated_in_a_row >= tries)
            self.docker.start_place(slot, pose, retreat, v0=v0, gate=gate)
            self._event(self.t, f"docking to place the {self.carrying.label} part in {self.target}"
                        + ("" if gate else f" (ungated: the gate stopped the last {self.gated_in_a_row})"))
            self._released_t = self._release_pose = None
            self.mode = "place"
            self._mode_t0 = self.t

    def _dock_done(self, pose) -> None:
        if self.mode == "floor_pick":
            self._floor_picked(pose)
            return
        if self.mode == "pick":
            self.counters.picks += 1
            self.gated_in_a_row = 0
            self.carrying = self.task.part
            self._held_pose = tuple(pose[:3])
            self._event(self.t, f"picked the {self.carrying.label} part from {self.target}")
            self.state = self.state.with_slot(self.task.source, None)  # expected until the server says
            self._held_state = self.state
            self.target = self.task.target
            dest = self._planned(self._usable(self.policy.destinations(self.state.with_slot(self.task.source, None),
                                                                       self.carrying)))
            if not self.settings.tasks.choose_by_time and self.target not in dest:  # the planned place was taken
                self.target = dest[0] if dest else None
            if not dest:
                self.mode, self.need_state_after = "decide", self.t
                return
            self._leg_replans = 0
            chosen = self.ahead.take(lambda key: self._ahead_still(key, pose, dest))
            if chosen is not None:  # chosen while backing out, for these inputs and about this pose
                self.counters.choices_ahead += 1
                self.target, leg, obstacles, planned_at = chosen
                if leg is not None and _near(pose, planned_at, AHEAD_LEG_POSE):  # where it was planned from
                    self.counters.legs_ahead += 1
                    self._start_planned("to_place", leg)
                else:  # the leg to the chosen destination from here
                    self._go("to_place", pose, obstacles)
                return
            self._go_fastest("to_place", pose, dest)
            return
        self.counters.places += 1
        self._event(self.t, f"placed the {self.carrying.label} part in {self.target}")
        self._placed = (self.target, tuple(pose[:3]))
        if self.settings.recovery.check_place and self.settings.recovery.refind:
            self.floor.placed(self.t, self.carrying, self._release_pose or tuple(pose[:3]), self.target,
                              self._held_state or self.state)
        if self.target.zone.startswith("machine"):  # from the release: t_seen - t_placed bounds the delay from above
            self.delays.placed(self.target, self.carrying, self._released_t if self._released_t is not None else self.t)
        self.state = self.state.with_slot(self.target, self.carrying)
        self.carrying = None
        self.magnet = False
        self.mode, self.need_state_after = "decide", self.t

    def _timeout(self, text: str) -> None:
        self.counters.timeouts += 1
        self._event(self.t, f"timeout: {text}")
        if self.mode == "to_floor":
            self._floor_failed("timeout", None)
            return
        if self.task is not None and isinstance(self.task, Move) and self.carrying is None:
            self.failures[self.task.source] = self.failures.get(self.task.source, 0) + 1
        self.follower.stop()
        self.mode, self.need_state_after = "decide", self.t

    def _dock_failed(self, reason: str, pose) -> None:
        if self.mode == "floor_pick":
            self._floor_failed(reason, pose)
            return
        self._event(self.t, f"{self.mode} at {self.target} failed: {reason}")
        if self.mode == "pick":
            self.failures[self.target] = self.failures.get(self.target, 0) + 1
        if self.mode == "pick":
            self.counters.pick_failures += 1
            self.magnet = False
            self.attempts += 1
            if reason in ("no_contact", "off_line") and self.attempts < self.settings.dock.retries:
                self._go("to_pick", pose)  # back to the approach pose, then try again
                return
            if reason == "part_lost" and self.settings.recovery.refind and isinstance(self.task, Move):
                # held, then let go backing out: if the server no longer lists it in its slot, it lies on the
                # floor between the slot and the robot (:meth:`_decide` asks)
                self.floor.let_go(self.t, self.task.part, pose, self.field.slot(self.target.zone, self.target.number),
                                  self.task.target, self.state)
        else:
            self.counters.place_failures += 1
            self.place_failed[self.target] = self.place_failed.get(self.target, 0) + 1
            self.gated_in_a_row = self.gated_in_a_row + 1 if reason == "off_line" else 0
            if reason == "still_held":
                self.magnet = False
        self.carrying = None if self.mode == "pick" else self.carrying
        self.mode, self.need_state_after = "decide", self.t

    def _docking(self) -> Docker:
        """The docker of the docking under way: the floor pick's own (:attr:`.FloorRecovery.docker`), or the slots'."""
        return self.floor.docker if self.mode == "floor_pick" else self.docker

    # ------------------------------------------------------------------------------------------ output
    def _follow(self, path, **kw) -> None:
        """Start the follower on ``path`` from the speeds last commanded (:meth:`_brake`, the relocalizer and the
        docker command without it: its own would be those it was stopped at)."""
        self.follower.start(path, speeds=(self._v, self._w), **kw)

    def _cmd(self, v: float, w: float) -> AgentCommand:
        self._v, self._w = v, w
        return AgentCommand(v, w, self.magnet)

    def _brake(self) -> AgentCommand:
        a, al = self.limits.a_max * self.dt, self.limits.alpha_max * self.dt
        self._v -= max(-a, min(a, self._v))
        self._w -= max(-al, min(al, self._w))
        return AgentCommand(self._v, self._w, self.magnet)

    def _event(self, t: float, text: str) -> None:
        self.events.append((t, text))


def _near(pose, at, within: tuple[float, float]) -> bool:
    """``pose`` is within ``within`` (m, rad) of ``at`` (x, y, heading)."""
    return (math.hypot(pose[0] - at[0], pose[1] - at[1]) <= within[0]
            and abs(math.remainder(pose[2] - at[2], 2 * math.pi)) <= within[1])


def _dock_of(mode: str) -> str:
    """The docking a leg in ``mode`` leads to: ``pick`` after ``to_pick``, else ``place``."""
    return "pick" if mode == "to_pick" else "place"
