"""The referee: scores a run from the factory's events, by the rules.

A *delivery* is a free part coming to rest in the right place for its type at that moment:
red in an input slot of machine A, green in an input slot of machine B, blue in the outgoing warehouse.
Each delivery earns one point, at most once per part and place, so a blue part scores 1, a green part up
to 2 (machine B, then outgoing as blue) and a red part up to 3 (A, B, outgoing). Only deliveries between
the run's start and the end of the round's duration count. Ties: more parts delivered to the outgoing
warehouse, then the shorter time (the last scoring delivery, in seconds since the start).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..field.model import Slot
from .factory import MACHINE_ACCEPTS, Factory, slot_label
from .parts import PartType


def is_delivery(part_type: PartType, slot: Slot) -> bool:
    """True when a part of this type resting in this slot is correctly placed (scores)."""
    if slot.zone == "outgoing":
        return part_type is PartType.BLUE
    return slot.role == "input" and MACHINE_ACCEPTS.get(slot.zone) is part_type


@dataclass(frozen=True)
class ScoreEvent:
    """One scoring delivery: at simulation time ``t`` (``elapsed`` s after the start)."""

    t: float
    elapsed: float
    part_id: int
    part_type: PartType
    slot: Slot
    points: int = 1

    @property
    def stage(self) -> str:
        """``machine_A``, ``machine_B`` or ``outgoing``: a part scores once per stage."""
        return self.slot.zone


@dataclass(frozen=True)
class ScoreReport:
    """A run's score at simulation time ``t``.

    ``points``: deliveries; ``outgoing``: parts delivered to the outgoing warehouse (first tie-break);
    ``last_score_time``: seconds from the start to the last scoring delivery (second tie-break, None when
    nothing scored); ``events``: the deliveries in time order; ``notes``: rule breaches seen (a false start,
    the robot outside the start area), which do not change the score.
    """

    points: int
    outgoing: int
    last_score_time: float | None
    events: tuple[ScoreEvent, ...]
    t: float
    start_time: float | None
    time_left: float
    round_no: int
    layout: str
    max_points: int
    notes: tuple[str, ...] = ()

    @property
    def started(self) -> bool:
        return self.start_time is not None

    def rank_key(self) -> tuple:
        """Sort runs best first: ``sorted(reports, key=ScoreReport.rank_key)``."""
        time = self.last_score_time if self.last_score_time is not None else math.inf
        return (-self.points, -self.outgoing, time)

    def beats(self, other: ScoreReport) -> bool:
        return self.rank_key() < other.rank_key()

    def short(self) -> str:
        """One line for a status display: ``score 4/6 (outgoing 1, last at 87.3 s)``."""
        if not self.started:
            return f"score -/{self.max_points} (not started)"
        last = f", last at {self.last_score_time:.1f} s" if self.last_score_time is not None else ""
        return f"score {self.points}/{self.max_points} (outgoing {self.outgoing}{last})"

    def __str__(self) -> str:
        head = f"Round {self.round_no}, incoming {self.layout}: "
        if not self.started:
            return "\n".join([head + f"run not started (t = {self.t:.2f} s), no score"]
                             + [f"  note: {n}" for n in self.notes])
        lines = [head + f"run started at t = {self.start_time:.2f} s, report at t = {self.t:.2f} s, "
                        f"{self.time_left:.1f} s left"]
        if self.events:
            lines.append(f"  {'time (s)':>8}  {'part':>4}  {'type':<5}  {'delivered to':<38}  points")
            for e in self.events:
                lines.append(f"  {e.elapsed:8.2f}  {e.part_id:4d}  {e.part_type.label:<5}  "
                             f"{slot_label(e.slot):<38}  {e.points:+d}")
        else:
            lines.append("  no delivery yet")
        last = f"{self.last_score_time:.2f} s" if self.last_score_time is not None else "-"
        lines.append(f"  total: {self.points} of {self.max_points} points; {self.outgoing} part(s) in the "
                     f"outgoing warehouse; time of the last score {last}")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


class Referee:
    """Scores the run of ``factory`` (reads its event log; holds no state of its own)."""

    def __init__(self, factory: Factory):
        self.factory = factory

    def report(self, t: float) -> ScoreReport:
        """The score of the run as of simulation time ``t`` (deliveries after the round's end are ignored)."""
        f = self.factory
        t = float(t)
        start = f.start_time
        events = f.events
        setup = f.setup
        base = dict(t=t, start_time=start, time_left=f.time_left(t), round_no=setup.round_no,
                    layout=setup.letters, max_points=setup.max_points, notes=tuple(f.rule_notes()))
        if start is None:
            return ScoreReport(0, 0, None, (), **base)
        end = min(t, start + setup.duration)
        seen: set[tuple[int, str]] = set()
        scored: list[ScoreEvent] = []
        running = False  # the log's order decides: a placement logged before the start never counts
        for e in events:
            if e.kind == "start":
                running = True
                continue
            if not running or e.kind != "placed" or e.slot is None or e.part_type is None:
                continue
            if not (start <= e.t <= end) or not is_delivery(e.part_type, e.slot):
                continue
            key = (e.part_id, e.slot.zone)
            if key in seen:
                continue
            seen.add(key)
            scored.append(ScoreEvent(e.t, e.t - start, e.part_id, e.part_type, e.slot))
        points = sum(s.points for s in scored)
        outgoing = sum(1 for s in scored if s.stage == "outgoing")
        last = max((s.elapsed for s in scored), default=None)
        return ScoreReport(points, outgoing, last, tuple(scored), **base)
