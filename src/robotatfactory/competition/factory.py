"""The factory's live state: which part is in which slot, the run's clock, and the two machines.

The simulator owns the physics; each control cycle it calls :meth:`Factory.step` with the parts' positions
(world x, y in metres), the robot's position and the parts the electromagnet holds. The factory decides
which slot each part is in and runs the machines; a machine that finishes a part returns a
:class:`Teleport`, which the simulator must apply (move and recolour the part). The stand-in applies it before
the next step; the real SimTwo, through the bridge (``raf referee``), a few cycles later. Until the positions show
the part at its output slot (at most ``TELEPORT_GRACE`` s), the state counts it there and its input slot empty,
as a simulator that moves it at once would: a robot told that the input slot holds a finished part would go there
for a part that is no longer there.

Thread-safe: the simulator steps while the factory-state server's thread reads (one re-entrant lock).
Times are simulation seconds; the run starts when the organiser calls :meth:`Factory.start`.
"""
from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass

from ..errors import ConfigError
from ..field.model import Field, Slot
from ..ratelog import RateLimitedLog
from .parts import PartType, letter_of
from .rounds import RoundSetup

log = logging.getLogger(__name__)

DEFAULT_TOLERANCE = 0.03  # m: a part is in a slot when its centre is this close (SimTwo's Lite scene)
DEFAULT_ROBOT_CLEARANCE = 0.17  # m: a machine starts only when the robot is farther from the input slot
FALSE_START_DISTANCE = 0.02  # m: the robot moving farther than this before the start is a false start
TELEPORT_GRACE = 1.0  # s of simulation time a teleport may take to show in the positions (SimTwo: 0.1-0.2 s)

ZONES = ("incoming", "outgoing", "machine_A", "machine_B")
MACHINE_ACCEPTS = {"machine_A": PartType.RED, "machine_B": PartType.GREEN}


@dataclass(frozen=True)
class Teleport:
    """Move part ``part_id`` to ``slot`` (centre ``slot.xy``, plate heading ``slot.facing``), now ``new_type``."""

    part_id: int
    slot: Slot
    new_type: PartType

    @property
    def xy(self) -> tuple[float, float]:
        return self.slot.xy

    @property
    def facing(self) -> float:
        return self.slot.facing


@dataclass(frozen=True)
class FactoryEvent:
    """Something that happened at simulation time ``t``.

    kinds: ``start`` (the run started), ``placed`` (a free part came to rest in ``slot``), ``left`` (it left
    ``slot``: taken, pushed or picked up), ``processing`` (a machine took it), ``cancelled`` (it was taken
    away before the machine finished), ``processed`` (the machine gave it back at ``slot``, now
    ``part_type``). ``part_type`` is the part's type at that moment. Rule notes (no effect on the score):
    ``false_start`` (the robot moved before the start), ``outside_start_area`` (the robot was not in the
    start area when the run started).
    """

    t: float
    kind: str
    part_id: int | None = None
    part_type: PartType | None = None
    slot: Slot | None = None
    note: str = ""

    def __str__(self) -> str:
        what = f" part {self.part_id} ({self.part_type.label})" if self.part_id is not None else ""
        where = f" at {slot_label(self.slot)}" if self.slot is not None else ""
        note = f": {self.note}" if self.note else ""
        return f"{self.t:8.2f} s {self.kind}{what}{where}{note}"


@dataclass(frozen=True)
class Lane:
    """One input slot of a machine and the output slot it feeds (machine slot 1 -> 2, 3 -> 4)."""

    machine: str
    input: Slot
    output: Slot


@dataclass
class Job:
    """A part being processed on ``lane`` since ``started``; ready at ``done_at`` (simulation seconds)."""

    part_id: int
    lane: Lane
    started: float
    done_at: float


@dataclass(frozen=True)
class PartState:
    """A part now: its type, the slot it is in (None: between slots or held) and whether it is held."""

    part_id: int
    part_type: PartType
    slot: Slot | None
    held: bool


def _several(robot_xy) -> bool:
    """True when ``robot_xy`` is a list of positions (several robots) rather than one (x, y)."""
    try:
        first = robot_xy[0]
    except (TypeError, IndexError, KeyError):
        return False
    return isinstance(first, (tuple, list)) or hasattr(first, "__len__")


def slot_label(slot: Slot) -> str:
    """``machine A slot 1 (input)``, ``outgoing warehouse slot 3``."""
    zone = {"incoming": "incoming warehouse", "outgoing": "outgoing warehouse",
            "machine_A": "machine A", "machine_B": "machine B"}.get(slot.zone, slot.zone)
    role = f" ({slot.role})" if slot.role != "store" else ""
    return f"{zone} slot {slot.number}{role}"


def machine_lanes(field: Field) -> list[Lane]:
    """Pair every machine input slot n with output slot n+1 of the same machine; FieldError-free check."""
    lanes = []
    for zone in MACHINE_ACCEPTS:
        slots = {s.number: s for s in field.slots_of(zone)}
        for n, s in sorted(slots.items()):
            if s.role != "input":
                continue
            out = slots.get(n + 1)
            if out is None or out.role != "output":
                raise ConfigError(f"field {field.name!r}: {zone} input slot {n} has no output slot {n + 1}")
            lanes.append(Lane(zone, s, out))
        if not any(lane.machine == zone for lane in lanes):
            raise ConfigError(f"field {field.name!r}: {zone} has no input slot")
    return lanes


class Factory:
    """The factory of one round. See the module docstring; docs/competition.md has the rules as built.

    Part ids are the incoming slot numbers the parts start in (1-4); an ``X`` slot has no part.
    """

    def __init__(self, field: Field, setup: RoundSetup, *, tolerance: float = DEFAULT_TOLERANCE,
                 robot_clearance: float = DEFAULT_ROBOT_CLEARANCE):
        if not (math.isfinite(tolerance) and tolerance > 0):
            raise ConfigError(f"slot tolerance must be a positive distance in metres, got {tolerance!r}")
        if not (math.isfinite(robot_clearance) and robot_clearance >= 0):
            raise ConfigError(f"robot clearance must be a distance >= 0 in metres, got {robot_clearance!r}")
        self.field = field
        self.setup = setup
        self.tolerance = float(tolerance)
        self.robot_clearance = float(robot_clearance)
        self.lanes: tuple[Lane, ...] = tuple(machine_lanes(field))
        self._slots: tuple[Slot, ...] = tuple(s for z in ZONES for s in field.slots_of(z))
        incoming = field.slots_of("incoming")
        if len(incoming) != len(setup.incoming):
            raise ConfigError(f"field {field.name!r} has {len(incoming)} incoming slots, the round needs "
                              f"{len(setup.incoming)}")
        self._initial = [(slot.number, p, slot) for slot, p in zip(incoming, setup.incoming) if p is not None]
        self._lock = threading.RLock()
        self._types: dict[int, PartType] = {pid: p for pid, p, _ in self._initial}
        self._where: dict[int, Slot] = {pid: slot for pid, _, slot in self._initial}
        self._held: set[int] = set()
        self._jobs: dict[Slot, Job] = {}
        self._moving: dict[int, tuple[Slot, float]] = {}  # teleports not yet seen in the positions: slot, until t
        self._events: list[FactoryEvent] = []
        self._start: float | None = None
        self._last_t: float | None = None
        self._robot_before: dict[int, tuple[float, float]] = {}  # per robot: first position seen before the start
        self._false_start = False
        self._robot_checked = False
        self._counters = dict(steps=0, bad_time=0, bad_positions=0, bad_held=0, unknown_parts=0, missing_parts=0,
                              bad_robot=0, processing=0, processed=0, cancelled=0, teleports_late=0,
                              internal_errors=0)
        self._rlog = RateLimitedLog(log)
        self._warned_unknown: set = set()

    # ----------------------------------------------------------------------------------------------- setup
    def initial_parts(self) -> list[tuple[int, PartType, Slot]]:
        """(part_id, type, incoming slot) for every part of the round, in slot order."""
        return list(self._initial)

    @property
    def part_ids(self) -> list[int]:
        return [pid for pid, _, _ in self._initial]

    # ------------------------------------------------------------------------------------------ run clock
    def start(self, t: float) -> bool:
        """Start the run at simulation time ``t`` (the organiser's signal). A second call is ignored
        (returns False); the first one returns True."""
        t = float(t)
        if not math.isfinite(t):
            raise ConfigError(f"start time must be finite, got {t!r}")
        with self._lock:
            if self._start is not None:
                log.warning("run already started at %.3f s; start(%.3f) ignored", self._start, t)
                return False
            self._start = t
            self._events.append(FactoryEvent(t, "start"))
            return True

    @property
    def started(self) -> bool:
        with self._lock:
            return self._start is not None

    @property
    def start_time(self) -> float | None:
        """Simulation time the run started, or None."""
        with self._lock:
            return self._start

    @property
    def end_time(self) -> float | None:
        """Simulation time the round's duration runs out, or None before the start."""
        with self._lock:
            return None if self._start is None else self._start + self.setup.duration

    def time_left(self, t: float) -> float:
        """Seconds left in the round at time ``t``: the full duration before the start, never below 0."""
        with self._lock:
            if self._start is None:
                return self.setup.duration
            return max(0.0, self.setup.duration - (float(t) - self._start))

    def running(self, t: float) -> bool:
        """True between the start and the end of the round (machines work only then)."""
        with self._lock:
            return self._start is not None and self._start <= t < self._start + self.setup.duration

    def over(self, t: float) -> bool:
        with self._lock:
            return self._start is not None and t >= self._start + self.setup.duration

    # ------------------------------------------------------------------------------------------ the state
    def letters(self, zone: str) -> str:
        """A zone's four slots as the server spells them, slot 1 first: e.g. ``"BGGR"``, ``"BXXG"``."""
        if zone not in ZONES:
            raise ValueError(f"unknown zone {zone!r}: one of {', '.join(ZONES)}")
        with self._lock:
            inside = {slot: pid for pid, slot in self._where.items()}
            return "".join(letter_of(self._types[inside[s]] if s in inside else None)
                           for s in self.field.slots_of(zone))

    def part_type(self, part_id: int) -> PartType:
        with self._lock:
            return self._types[part_id]

    def slot_of(self, part_id: int) -> Slot | None:
        """The slot the part is in now (None: between slots, held or unknown)."""
        with self._lock:
            return self._where.get(part_id)

    def parts(self) -> list[PartState]:
        with self._lock:
            return [PartState(pid, self._types[pid], self._where.get(pid), pid in self._held)
                    for pid in self.part_ids]

    def jobs(self) -> list[Job]:
        """Parts being processed now (copies)."""
        with self._lock:
            return [Job(j.part_id, j.lane, j.started, j.done_at) for j in self._jobs.values()]

    @property
    def events(self) -> list[FactoryEvent]:
        """Everything that happened so far, in order (a copy)."""
        with self._lock:
            return list(self._events)

    @property
    def counters(self) -> dict[str, int]:
        """steps, rejected inputs (bad_time, bad_positions, bad_held, unknown_parts, missing_parts, bad_robot),
        machine activity (processing, processed, cancelled), teleports_late (a teleport not seen in the positions
        within TELEPORT_GRACE) and internal_errors (bugs caught in step)."""
        with self._lock:
            return dict(self._counters)

    # -------------------------------------------------------------------------------------------- a cycle
    def step(self, t: float, part_xy, robot_xy, held=()) -> list[Teleport]:
        """Update the state from the simulator's cycle at time ``t`` and run the machines.

        ``part_xy``: {part_id: (x, y)} world metres of each part's centre; ``robot_xy``: (x, y) of the
        robot (base_link), or a list of them, one per robot, when several robots share the field (a machine
        starts only when every robot is clear of its input slot; every robot must start in the start area);
        ``held``: ids of the parts the electromagnets hold (a held part is in no slot).
        Bad entries (unknown ids, non-finite numbers) are counted, logged and ignored; a part that is not
        reported is in no slot. Returns the teleports the simulator must apply before the next step.
        """
        with self._lock:
            self._counters["steps"] += 1
            try:
                return self._step(t, part_xy, robot_xy, held)
            except Exception as e:  # a bug must not stop the simulator: count, log, carry on
                self._counters["internal_errors"] += 1
                self._rlog.warn("internal", "factory step failed (state kept): %r", e)
                return []

    def _step(self, t, part_xy, robot_xy, held) -> list[Teleport]:
        """:meth:`step` without the safety net (runs under the lock)."""
        try:
            t = float(t)
        except (TypeError, ValueError, OverflowError):
            t = math.nan
        if not math.isfinite(t):
            self._counters["bad_time"] += 1
            self._rlog.warn("bad_time", "factory step with a bad time %r ignored", t)
            return []
        if self._last_t is not None and t < self._last_t:
            self._counters["bad_time"] += 1
            self._rlog.warn("time_back", "factory time went back from %.3f to %.3f s", self._last_t, t)
        self._last_t = t
        held_ids = self._clean_held(held)
        positions = self._clean_positions(part_xy)
        several = _several(robot_xy)
        robots = [self._clean_xy(r) for r in robot_xy] if several else [self._clean_xy(robot_xy)]
        if not robots or any(r is None for r in robots):
            robots = None
            self._counters["bad_robot"] += 1
            self._rlog.warn("bad_robot", "bad robot position %r: machines wait", robot_xy)
        self._held = held_ids
        if robots is not None:
            for k, robot in enumerate(robots):
                self._check_robot(t, robot, k if several else None)
            self._robot_checked = self._robot_checked or (self._start is not None and t >= self._start)
        self._update_slots(t, positions, held_ids)
        if not self.running(t):
            return []
        return self._run_machines(t, robots)

    # ------------------------------------------------------------------------------------------ internals
    def _check_robot(self, t: float, robot: tuple[float, float], k: int | None = None) -> None:
        """Rule notes: the robot (``k``: robot k + 1 of several) must not move before the start and must
        start in the start area."""
        who = "the robot" if k is None else f"robot {k + 1}"
        key = 0 if k is None else k
        if self._start is None or t < self._start:
            before = self._robot_before.get(key)
            if before is None:
                self._robot_before[key] = robot
            elif not self._false_start and math.dist(robot, before) > FALSE_START_DISTANCE:
                self._false_start = True
                self._events.append(FactoryEvent(t, "false_start", note=(
                    f"{who} moved {math.dist(robot, before):.3f} m before the run started")))
        elif not self._robot_checked:
            if not self.field.start_area.contains(*robot):
                self._events.append(FactoryEvent(t, "outside_start_area", note=(
                    f"{who} was at ({robot[0]:.3f}, {robot[1]:.3f}) m when the run started, outside the "
                    f"start area x {self.field.start_area.x}, y {self.field.start_area.y}")))

    def rule_notes(self) -> list[str]:
        """Breaches of the rules seen so far (they do not change the score; an organiser would rule)."""
        with self._lock:
            return [e.note for e in self._events if e.kind in ("false_start", "outside_start_area")]

    def _clean_held(self, held) -> set[int]:
        out = set()
        try:
            items = list(held or ())
        except TypeError:
            self._counters["bad_held"] += 1
            self._rlog.warn("bad_held", "held parts must be a collection of ids, got %r", held)
            return out
        for pid in items:
            try:
                known = pid in self._types
            except TypeError:  # unhashable junk
                known = False
            if known:
                out.add(pid)
            else:
                self._counters["unknown_parts"] += 1
                self._rlog.warn("unknown_held", "held part id %r is not a part of this round", pid)
        return out

    def _clean_positions(self, part_xy) -> dict[int, tuple[float, float]]:
        out = {}
        try:
            items = list(dict(part_xy or {}).items())
        except (TypeError, ValueError):
            self._counters["bad_positions"] += 1
            self._rlog.warn("bad_part_xy", "part positions must map id -> (x, y), got %r", type(part_xy))
            return out
        for pid, xy in items:
            if pid not in self._types:
                self._counters["unknown_parts"] += 1
                if pid not in self._warned_unknown and len(self._warned_unknown) < 100:
                    self._warned_unknown.add(pid)  # once per id: a simulator may hold extra parts
                    log.warning("part id %r is not a part of this round: the factory ignores it", pid)
                continue
            p = self._clean_xy(xy)
            if p is None:
                self._counters["bad_positions"] += 1
                self._rlog.warn("bad_xy", "bad position %r of part %r: in no slot", xy, pid)
                continue
            out[pid] = p
        missing = len(self._types) - len(out)
        if missing > 0:
            self._counters["missing_parts"] += missing
        return out

    @staticmethod
    def _clean_xy(xy) -> tuple[float, float] | None:
        try:
            x, y = float(xy[0]), float(xy[1])
        except (TypeError, ValueError, IndexError, KeyError, OverflowError):
            return None
        if not (math.isfinite(x) and math.isfinite(y)):
            return None
        return x, y

    def _update_slots(self, t: float, positions: dict[int, tuple[float, float]], held: set[int]) -> None:
        # each free part goes to its nearest slot within tolerance; a slot keeps only its nearest claimant
        claims: dict[Slot, tuple[float, int]] = {}
        moving = self._teleports_in_flight(t, positions)
        for pid, (x, y) in positions.items():
            if pid in held or pid in moving:
                continue
            best = None
            for s in self._slots:
                d = math.hypot(x - s.xy[0], y - s.xy[1])
                if d <= self.tolerance and (best is None or d < best[0]):
                    best = (d, s)
            if best is None:
                continue
            d, s = best
            if s not in claims or (d, pid) < claims[s]:
                claims[s] = (d, pid)
        where = {pid: s for s, (_, pid) in claims.items()}
        for pid, slot in moving.items():  # on its way to the output: there already, unless another part is or
            if slot not in claims and pid not in held:  # a magnet has it meanwhile (a held part is in no slot)
                where[pid] = slot
        for pid in self.part_ids:
            old, new = self._where.get(pid), where.get(pid)
            if old == new:
                continue
            ptype = self._types[pid]
            if old is not None:
                self._events.append(FactoryEvent(t, "left", pid, ptype, old))
            if new is not None:
                self._events.append(FactoryEvent(t, "placed", pid, ptype, new, self._placement_note(ptype, new)))
        self._where = where

    def _teleports_in_flight(self, t: float, positions: dict[int, tuple[float, float]]) -> dict[int, Slot]:
        """The parts a machine has sent to its output whose positions do not show them there yet, within
        ``TELEPORT_GRACE``; a teleport seen in the positions, or late, is forgotten (late: counted, logged)."""
        out = {}
        for pid, (slot, until) in list(self._moving.items()):
            xy = positions.get(pid)
            if xy is not None and math.hypot(xy[0] - slot.xy[0], xy[1] - slot.xy[1]) <= self.tolerance:
                del self._moving[pid]
            elif t > until:
                del self._moving[pid]
                self._counters["teleports_late"] += 1
                self._rlog.warn("teleport_late", "part %d not at %s %.1f s after its teleport: its position "
                                "counts again", pid, slot_label(slot), TELEPORT_GRACE)
            else:
                out[pid] = slot
        return out

    @staticmethod
    def _placement_note(ptype: PartType, slot: Slot) -> str:
        if slot.role == "input" and MACHINE_ACCEPTS.get(slot.zone) is not ptype:
            want = MACHINE_ACCEPTS.get(slot.zone)
            return f"wrong type: {slot_label(slot).split(' slot')[0]} processes {want.label} parts only"
        return ""

    def _run_machines(self, t: float, robots: list[tuple[float, float]] | None) -> list[Teleport]:
        teleports = []
        occupied = {slot: pid for pid, slot in self._where.items()}
        for lane in self.lanes:
            job = self._jobs.get(lane.input)
            if job is not None and self._where.get(job.part_id) != lane.input:
                del self._jobs[lane.input]
                self._counters["cancelled"] += 1
                self._events.append(FactoryEvent(t, "cancelled", job.part_id, self._types[job.part_id], lane.input,
                                                 "taken away before the machine finished"))
                job = None
            if job is None:
                pid = occupied.get(lane.input)
                if pid is None or self._types[pid] is not MACHINE_ACCEPTS[lane.machine]:
                    continue  # empty, or a part this machine does not process (it stays there)
                if lane.output in occupied:
                    continue
                if robots is None or any(math.hypot(r[0] - lane.input.xy[0], r[1] - lane.input.xy[1])
                                         <= self.robot_clearance for r in robots):
                    continue  # no robot position, or a robot too near the input slot
                job = Job(pid, lane, t, t + self.setup.processing_delay)
                self._jobs[lane.input] = job
                self._counters["processing"] += 1
                self._events.append(FactoryEvent(t, "processing", pid, self._types[pid], lane.input))
            if t < job.done_at or lane.output in occupied:
                continue  # still working, or waiting for someone to clear the output slot
            del self._jobs[lane.input]
            new_type = self._types[job.part_id].next()
            self._types[job.part_id] = new_type
            # the state shows it at its output at once, and until the positions do (TELEPORT_GRACE)
            self._where[job.part_id] = lane.output
            self._moving[job.part_id] = (lane.output, t + TELEPORT_GRACE)
            occupied.pop(lane.input, None)
            occupied[lane.output] = job.part_id
            self._counters["processed"] += 1
            self._events.append(FactoryEvent(t, "processed", job.part_id, new_type, lane.output))
            teleports.append(Teleport(job.part_id, lane.output, new_type))
        return teleports
