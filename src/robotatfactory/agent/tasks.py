"""The round's task logic: which part to move where next, and the whole round's plan.

Rules (docs/competition.md): red goes to a machine A input, green to a machine B input, blue to the
outgoing warehouse; a machine turns the part at an input into the next type at the lane's output after
the processing delay, if that output is free. The policy works only on what the server says
(:class:`~.state.FactoryState`), so re-planning is asking it again: every decision is made from the
latest state, and :func:`plan_round` simulates the same policy forward to show the whole round.

Decisions:

* A part is **settled** when it is blue in the outgoing warehouse or in an input of the machine that
  processes its type (the machine will take it). Every other part is a candidate to move.
* **Picking order:** the part with the most machine stages ahead first (red, then green, then blue: a red
  part needs two processing delays, so the machines work while the robot carries the rest), among those
  a part waiting at a machine output first (it blocks its lane), then the nearest to the robot. Measured
  on the bare stand-in (ground truth, default limits), round 3 seeds 0-4, time of the last score: 159 / 202 /
  202 / 126 / 163 s; with every output first, then red, green, blue: 155 / 208 / 208 / 126 / 157 s. No
  clear gain either way: the driving, not the order, takes the time (docs/agent.md).
* **Free slots so parts never block each other:** a machine input whose lane output is free comes before
  one whose output is occupied (the machine would wait); an input is never chosen while its lane still
  has a part pending. Warehouse slots are side by side behind ribs and reached straight from the field,
  so any free one works; the one nearest to the part's source is taken.
* A part with no free destination is not picked (the robot would have to carry it around); the robot
  waits for a machine instead (:class:`Wait`), or the round is over (:class:`Done`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..competition.parts import PartType
from .delay import LaneRef
from .state import ZONES, FactoryState, SlotRef

MACHINE_OF = {PartType.RED: "machine_A", PartType.GREEN: "machine_B"}
_PRIORITY = {PartType.RED: 1, PartType.GREEN: 2, PartType.BLUE: 3}
#: a blue part from a machine output goes to one of this many free outgoing slots nearest the outputs
#: (:meth:`TaskPolicy.outgoing_near_outputs`), the ones it reaches turning one way only
NEAR_OUTPUT_SLOTS = 2


@dataclass(frozen=True)
class Move:
    """Take ``part`` (its type at the source) from ``source`` and leave it at ``target``."""

    part: PartType
    source: SlotRef
    target: SlotRef

    def __str__(self) -> str:
        return f"move {self.part.label} part from {self.source} to {self.target}"


@dataclass(frozen=True)
class Wait:
    """Nothing can be moved now: wait for machine output ``slot``; ``until`` is the expected time (s) or
    None when the delay is not known yet (poll the server)."""

    slot: SlotRef
    until: float | None = None

    def __str__(self) -> str:
        when = "" if self.until is None else f" until t = {self.until:.1f} s"
        return f"wait for {self.slot}{when}"


@dataclass(frozen=True)
class Done:
    """Every part is settled and no machine is working: the round is finished."""

    def __str__(self) -> str:
        return "done"


Task = Move | Wait | Done


class TaskPolicy:
    """The decisions above for one field. ``slot_xy`` maps a SlotRef to its centre (m, field frame)."""

    def __init__(self, lanes: list[LaneRef], slot_xy: dict[SlotRef, tuple[float, float]],
                 slot_facing: dict[SlotRef, float] | None = None):
        self.lanes = lanes
        self.slot_xy = slot_xy
        self.slot_facing = slot_facing or {}  # rad, the heading of a slot's plate (towards the robot)
        self._lane_of = {ln.input: ln for ln in lanes} | {ln.output: ln for ln in lanes}
        self._outputs = {ln.output for ln in lanes}

    @classmethod
    def for_field(cls, field) -> TaskPolicy:
        from .delay import lanes_of

        return cls(lanes_of(field), {SlotRef(s.zone, s.number): tuple(s.xy) for s in field.slots},
                   {SlotRef(s.zone, s.number): float(s.facing) for s in field.slots})

    # -------------------------------------------------------------------------------------- queries
    def is_settled(self, ref: SlotRef, part: PartType) -> bool:
        if ref.zone == "outgoing":
            return part is PartType.BLUE
        lane = self._lane_of.get(ref)
        return lane is not None and lane.input == ref and MACHINE_OF.get(part) == lane.machine

    def _dist(self, a: SlotRef, b: SlotRef | tuple[float, float]) -> float:
        pa = self.slot_xy[a]
        pb = b if isinstance(b, tuple) else self.slot_xy[b]
        return math.hypot(pa[0] - pb[0], pa[1] - pb[1])

    def destinations(self, state: FactoryState, part: PartType, source: SlotRef | None = None) -> list[SlotRef]:
        """Free slots where ``part`` scores, best first (see the module's decisions)."""
        near = source if source is not None else None
        if part is PartType.BLUE:
            free = [SlotRef("outgoing", n) for n in range(1, 5) if state.outgoing[n - 1] is None]
            return sorted(free, key=lambda r: (self._dist(r, near) if near else 0.0, r.number))
        machine = MACHINE_OF[part]
        ranked = []
        for ln in self.lanes:
            if ln.machine != machine or state.at(ln.input) is not None:
                continue
            blocked = state.at(ln.output) is not None
            ranked.append(((blocked, self._dist(ln.input, near) if near else 0.0, ln.input.number), ln.input))
        return [r for _, r in sorted(ranked)]

    def destination_class(self, state: FactoryState, ref: SlotRef) -> int:
        """The rank of a free destination that :meth:`destinations` sorts by before distance: 1 for a machine
        input whose lane output is occupied (the machine would wait), else 0."""
        lane = self._lane_of.get(ref)
        return int(lane is not None and state.at(lane.output) is not None)

    def lane_of(self, ref: SlotRef | None) -> LaneRef | None:
        """The machine lane whose input or output ``ref`` is (None: a warehouse slot)."""
        return self._lane_of.get(ref)

    def is_output(self, ref: SlotRef | None) -> bool:
        return ref in self._outputs

    def outgoing_near_outputs(self, state: FactoryState, ahead: float = 0.26) -> list[SlotRef]:
        """The free outgoing slots, nearest first to where the robot stands after taking a part from one of the
        machine outputs that give blue parts (:meth:`outgoing_by_nearness`)."""
        return [r for r in self.outgoing_by_nearness(ahead) if state.outgoing[r.number - 1] is None]

    def outgoing_by_nearness(self, ahead: float = 0.26) -> list[SlotRef]:
        """Every outgoing slot, nearest first to where the robot stands after taking a part from one of the
        machine outputs that give blue parts (``ahead`` m out along their facing, averaged): from there it
        reaches the first ones with turns one way only, while to the far ones it turns back the other way after
        its first turn on the spot, when the carried part has slid along the magnet's face (SimTwo's force
        magnet), and the part may pivot off it (lost in 5 of 10 runs on a late, noisy pose, docs/agent.md)."""
        every = [SlotRef("outgoing", k) for k in range(1, 5)]
        final_outputs = [ln.output for ln in self.lanes if ln.machine == MACHINE_OF[PartType.GREEN]]
        if not final_outputs:
            return every
        pts = [(self.slot_xy[o][0] + ahead * math.cos(self.slot_facing.get(o, 0.0)),
                self.slot_xy[o][1] + ahead * math.sin(self.slot_facing.get(o, 0.0))) for o in final_outputs]
        mx = sum(p[0] for p in pts) / len(pts)
        my = sum(p[1] for p in pts) / len(pts)
        return sorted(every, key=lambda r: (self._dist(r, (mx, my)), r.number))

    def reserved_outgoing(self, state: FactoryState, source: SlotRef | None = None) -> list[SlotRef]:
        """Free outgoing slots to keep for the blue parts that will still come out of machine outputs, when a
        blue part from ``source`` (not a machine output) is to be placed: as many as there are such parts
        (every red or green part, every blue one at a machine output, the one at ``source`` not counted) of
        :meth:`outgoing_near_outputs`."""
        if source in self._outputs:
            return []
        n = 0
        for zone in ZONES:
            for k, part in enumerate(state.zone(zone), start=1):
                ref = SlotRef(zone, k)
                if part is None or ref == source:
                    continue
                if part is not PartType.BLUE or ref in self._outputs:
                    n += 1
        return self.outgoing_near_outputs(state)[:n] if n else []

    def candidates(self, state: FactoryState, avoid: frozenset[SlotRef] | set[SlotRef] = frozenset()) -> list[Move]:
        """Every part that should move and has a free destination, in picking order."""
        moves = []
        for zone in ZONES:
            for n, part in enumerate(state.zone(zone), start=1):
                ref = SlotRef(zone, n)
                if part is None or self.is_settled(ref, part) or ref in avoid:
                    continue
                dest = self.destinations(state, part, ref)
                if dest:
                    moves.append(Move(part, ref, dest[0]))
        return sorted(moves, key=lambda m: (*self._rank(m), m.source))

    def _rank(self, m: Move) -> tuple[int, bool]:
        """Most machine stages still ahead first (red, green, blue); a part at an output before one
        elsewhere."""
        return _PRIORITY[m.part], m.source not in self._outputs

    def tied(self, state: FactoryState, avoid: frozenset[SlotRef] | set[SlotRef] = frozenset()) -> list[Move]:
        """The candidates of the best rank (:meth:`next_task` picks among them by distance; the agent may pick by
        time instead)."""
        moves = self.candidates(state, avoid)
        return [m for m in moves if self._rank(m) == self._rank(moves[0])] if moves else []

    def next_task(self, state: FactoryState, robot_xy: tuple[float, float] | None = None,
                  ready_at: dict[SlotRef, float] | None = None,
                  avoid: frozenset[SlotRef] | set[SlotRef] = frozenset()) -> Task:
        """The next task from the server's state. ``robot_xy`` (m) breaks ties by distance;
        ``ready_at`` maps machine inputs to the expected ready time of their part (s); parts in the slots
        of ``avoid`` are not picked (the agent gave up on them after repeated failures)."""
        moves = self.candidates(state, avoid)
        if moves:
            best_rank = self._rank(moves[0])
            same = [m for m in moves if self._rank(m) == best_rank]
            if robot_xy is not None:
                same.sort(key=lambda m: self._dist(m.source, tuple(robot_xy)))
            return same[0]
        working = [ln for ln in self.lanes if state.at(ln.input) is not None
                   and self.is_settled(ln.input, state.at(ln.input))]
        if working:
            ready = ready_at or {}
            working.sort(key=lambda ln: ready.get(ln.input, math.inf))
            ln = working[0]
            return Wait(ln.output, ready.get(ln.input))
        return Done()


@dataclass(frozen=True)
class PlannedStep:
    """One step of a simulated round: the task, when it starts and ends (s from the plan's start)."""

    start: float
    end: float
    task: Task


def plan_round(policy: TaskPolicy, state: FactoryState, delay: float, move_time: float = 8.0,
               max_steps: int = 64) -> tuple[list[PlannedStep], FactoryState]:
    """Simulate the policy from ``state``: each Move takes ``move_time`` s, machines take ``delay`` s from
    the moment a part is left at their input (and an occupied output holds them). Returns the steps and
    the final state. For display and tests; the agent decides each task from the live server state."""
    t = 0.0
    jobs: dict[SlotRef, float] = {}  # machine input -> time the part is ready
    steps: list[PlannedStep] = []
    for _ in range(max_steps):
        state = _finish_jobs(policy, state, jobs, t)
        task = policy.next_task(state, ready_at=jobs)
        if isinstance(task, Done):
            steps.append(PlannedStep(t, t, task))
            return steps, state
        if isinstance(task, Wait):
            later = [v for v in jobs.values() if v > t]
            t_next = min(later) if later else t
            if t_next <= t:  # a processed part waits for its output to empty: nothing would change
                raise RuntimeError(f"plan stuck at {state}: {task}")
            steps.append(PlannedStep(t, t_next, task))
            t = t_next
            continue
        jobs.pop(task.source, None)
        state = state.with_slot(task.source, None).with_slot(task.target, task.part)
        steps.append(PlannedStep(t, t + move_time, task))
        t += move_time
        if policy.is_settled(task.target, task.part) and task.target.zone.startswith("machine"):
            jobs[task.target] = t + delay
    raise RuntimeError(f"no plan within {max_steps} steps from {state}")


def _finish_jobs(policy: TaskPolicy, state: FactoryState, jobs: dict[SlotRef, float], t: float) -> FactoryState:
    for ln in policy.lanes:
        done = jobs.get(ln.input)
        if done is not None and done <= t and state.at(ln.output) is None:
            part = state.at(ln.input)
            state = state.with_slot(ln.input, None).with_slot(ln.output, part.next())
            del jobs[ln.input]
    return state
