"""The referee: scores a run from the factory's events, as the rules count it.

The rules score "parts correctly placed in the outgoing warehouse or a machine": a part scores for the place
it **rests in at the end of the run**. Red belongs in an input slot of machine A, green in an input slot of
machine B, blue in the outgoing warehouse. A machine that processes a part takes it from its input and gives
it back, turned into the next type, at its output: that stage's point is banked (the part's new colour is
the proof it was delivered), so a blue part scores 1, a green part up to 2 (machine B, then outgoing as
blue) and a red part up to 3 (A, B, outgoing). A part that leaves a correct place by any other way (picked
up again, pushed or knocked more than 3 cm out of its slot) loses that place's point; put back, it scores
again. Only placements made during the run count (after the start, not after the round's duration); the
score at time ``t`` is the score the run would have if it ended then.

The **delivery time** (second tie-break) is when the final score was reached and held: the earliest time
since which the score never fell below its final value. Ties: more parts resting in the outgoing warehouse,
then the shorter delivery time. docs/competition.md has the decisions.
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
    """One change of the score at simulation time ``t`` (``elapsed`` s after the start): ``points`` +1 when
    part ``part_id`` of ``part_type`` came to rest in ``slot``, a correct place; -1 when it left that place
    (picked up, pushed or knocked out) before the end of the run."""

    t: float
    elapsed: float
    part_id: int
    part_type: PartType
    slot: Slot
    points: int = 1

    @property
    def stage(self) -> str:
        """``machine_A``, ``machine_B`` or ``outgoing``: a part scores at most once per stage."""
        return self.slot.zone

    @property
    def lost(self) -> bool:
        """True for a point taken back (the part left its correct place)."""
        return self.points < 0


@dataclass(frozen=True)
class ScoreReport:
    """A run's score at simulation time ``t`` (as if the run ended then).

    ``points``: parts' points (banked by machines, plus each part resting in a correct place);
    ``outgoing``: blue parts resting in the outgoing warehouse (first tie-break); ``last_score_time``: seconds
    from the start to when the final score was reached and held (second tie-break, None when nothing
    scored); ``events``: every change of the score in time order (+1 deliveries, -1 points lost);
    ``notes``: rule breaches seen (a false start, the robot outside the start area), which do not change the
    score. ``processed``, ``cancelled``, ``teleports_late``: the factory's counters of those names when the
    report was made (parts its machines gave back, jobs cancelled, teleports not seen in the positions within
    ``TELEPORT_GRACE``), not at ``t``: diagnostics, no part of the score.
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
    processed: int = 0
    cancelled: int = 0
    teleports_late: int = 0

    @property
    def started(self) -> bool:
        return self.start_time is not None

    @property
    def lost(self) -> int:
        """Points taken back during the run (parts that left a correct place)."""
        return -sum(e.points for e in self.events if e.lost)

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
            lines.append(f"  {'time (s)':>8}  {'part':>4}  {'type':<5}  {'delivered to / left':<41}  points")
            for e in self.events:
                where = ("left " if e.lost else "") + slot_label(e.slot)
                lines.append(f"  {e.elapsed:8.2f}  {e.part_id:4d}  {e.part_type.label:<5}  "
                             f"{where:<41}  {e.points:+d}")
        else:
            lines.append("  no delivery yet")
        last = f"{self.last_score_time:.2f} s" if self.last_score_time is not None else "-"
        lost = f"; {self.lost} point(s) lost on the way" if self.lost else ""
        lines.append(f"  total: {self.points} of {self.max_points} points; {self.outgoing} part(s) in the "
                     f"outgoing warehouse; time of the last score {last}{lost}")
        lines.append(f"  factory counters: processed {self.processed}, cancelled {self.cancelled}, "
                     f"teleports_late {self.teleports_late}")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


class Referee:
    """Scores the run of ``factory`` (replays its event log; holds no state of its own)."""

    def __init__(self, factory: Factory):
        self.factory = factory

    def report(self, t: float) -> ScoreReport:
        """The score of the run as if it ended at simulation time ``t`` (nothing after the round's end counts:
        the state at the end of the duration is the final one)."""
        f = self.factory
        t = float(t)
        start = f.start_time
        events = f.events
        setup = f.setup
        counters = f.counters
        base = dict(t=t, start_time=start, time_left=f.time_left(t), round_no=setup.round_no,
                    layout=setup.letters, max_points=setup.max_points, notes=tuple(f.rule_notes()),
                    **{k: counters[k] for k in ("processed", "cancelled", "teleports_late")})
        if start is None:
            return ScoreReport(0, 0, None, (), **base)
        end = min(t, start + setup.duration)
        # per part: the place it rests in now and whether that placement was made during the run
        resting: dict[int, tuple[Slot, PartType, bool]] = {}
        banked: dict[int, int] = {}  # stages a machine took the part through (points kept for good)
        changes: list[ScoreEvent] = []
        running = False  # the log's order decides: a placement logged before the start never counts
        for e in events:
            if e.t > end:
                break  # after the round's end (or the report's time): the state then is final
            if e.kind == "start":
                running = True
                continue
            if e.part_id is None or e.kind not in ("placed", "left", "processed"):
                continue
            before = resting.get(e.part_id)
            if e.kind == "placed" and e.slot is not None and e.part_type is not None:
                resting[e.part_id] = (e.slot, e.part_type, running)
            elif e.kind == "left":
                resting.pop(e.part_id, None)
            elif e.kind == "processed" and e.slot is not None and e.part_type is not None:
                if before is not None and before[2] and is_delivery(before[1], before[0]):
                    banked[e.part_id] = banked.get(e.part_id, 0) + 1  # the machine took a delivered part
                    before = None  # its point is kept: no loss below
                resting[e.part_id] = (e.slot, e.part_type, running)  # the output slot: never a delivery
            after = resting.get(e.part_id)
            was = before is not None and before[2] and is_delivery(before[1], before[0])
            now = after is not None and after[2] and is_delivery(after[1], after[0])
            if was and not now:
                changes.append(ScoreEvent(e.t, e.t - start, e.part_id, before[1], before[0], -1))
            elif now and not was:
                changes.append(ScoreEvent(e.t, e.t - start, e.part_id, after[1], after[0], +1))
        points = sum(banked.values()) + sum(1 for s, p, ok in resting.values() if ok and is_delivery(p, s))
        outgoing = sum(1 for s, p, ok in resting.values() if ok and s.zone == "outgoing" and is_delivery(p, s))
        return ScoreReport(points, outgoing, _held_since(changes, points), tuple(changes), **base)


def _held_since(changes: list[ScoreEvent], final: int) -> float | None:
    """Seconds from the start to when the score reached ``final`` and never fell below it again (None when
    the final score is 0). Changes of one cycle are taken together (a part moved between two correct slots
    in one cycle does not dip)."""
    if final <= 0:
        return None
    score, since = 0, None
    i = 0
    while i < len(changes):
        t = changes[i].t
        while i < len(changes) and changes[i].t == t:
            score += changes[i].points
            i += 1
        if score >= final:
            if since is None:
                since = changes[i - 1].elapsed
        else:
            since = None
    return since
