"""Learn the machines' processing delay from what the server shows (never assumed).

The agent tells :class:`DelayEstimator` when it left a part at a machine input (:meth:`placed`) and feeds
it every fresh :class:`~.state.FactoryState` (:meth:`update`). When the server shows that lane's input
empty and its output holding the processed type, ``t_seen - t_placed`` is an upper bound of the delay
(it includes the robot's leaving the input by 0.17 m and the poll period); the estimate is the smallest
bound seen. Times are the agent's clock in seconds (simulation time on the stand-in).
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..competition.parts import PartType
from .state import FactoryState, SlotRef


@dataclass(frozen=True)
class LaneRef:
    """A machine lane: ``input`` feeds ``output`` (server numbers: 1 -> 2, 3 -> 4)."""

    machine: str
    input: SlotRef
    output: SlotRef


def lanes_of(field) -> list[LaneRef]:
    """The field's machine lanes (from :func:`robotatfactory.competition.machine_lanes`)."""
    from ..competition import machine_lanes

    return [LaneRef(ln.machine, SlotRef(ln.input.zone, ln.input.number), SlotRef(ln.output.zone, ln.output.number))
            for ln in machine_lanes(field)]


@dataclass
class DelayEstimator:
    """Processing delay estimate (s); ``prior`` is used until the first observation (None: unknown)."""

    lanes: list[LaneRef]
    prior: float | None = None
    observations: list[float] = field(default_factory=list)
    _pending: dict[SlotRef, tuple[float, PartType]] = field(default_factory=dict)

    @property
    def estimate(self) -> float | None:
        """The smallest observed delay (s), else the prior."""
        return min(self.observations) if self.observations else self.prior

    def placed(self, input_slot: SlotRef, part: PartType, t: float) -> None:
        """The robot left ``part`` at machine input ``input_slot`` at time ``t`` (s)."""
        self._pending[input_slot] = (float(t), part)

    def placed_at(self, input_slot: SlotRef) -> float | None:
        """When the part now processing at ``input_slot`` was left there (None: nothing pending)."""
        p = self._pending.get(input_slot)
        return None if p is None else p[0]

    def expected_ready(self, input_slot: SlotRef) -> float | None:
        """When the part left at ``input_slot`` should appear at the output (s), None if unknown."""
        t0, est = self.placed_at(input_slot), self.estimate
        return None if t0 is None or est is None else t0 + est

    def update(self, state: FactoryState, t: float) -> float | None:
        """Look at a fresh server state seen at time ``t``; returns a new observation (s) or None."""
        seen = None
        for lane in self.lanes:
            p = self._pending.get(lane.input)
            if p is None:
                continue
            t0, part = p
            if state.at(lane.input) == part:
                continue  # still processing (or waiting for a free output)
            del self._pending[lane.input]
            try:
                processed = part.next()
            except ValueError:
                continue
            if state.at(lane.output) == processed and t >= t0:
                seen = t - t0
                self.observations.append(seen)
        return seen
