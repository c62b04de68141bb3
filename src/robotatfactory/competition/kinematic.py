"""A kinematic stand-in for the simulator's side of the factory: parts are points, the robot is a point,
picking and placing are instant. It steps a :class:`Factory` exactly as the simulator does and applies its
teleports: at once by default, or ``teleport_delay`` cycles later (or never), as the real SimTwo does through the
referee's bridge. For tests, scripted demonstrations and planners that need the factory without physics.

>>> from robotatfactory.field import load_field
>>> from robotatfactory.competition import RoundSetup
>>> w = KinematicWorld(load_field(), RoundSetup.make(1, parts="BXXX"))
>>> w.start()
>>> w.pick(1); w.place(1, "outgoing", 1)
>>> w.factory.letters("outgoing")
'BXXX'
>>> w.report().points
1
"""
from __future__ import annotations

from ..errors import ConfigError
from ..field.model import Field, Slot
from .factory import Factory, Teleport
from .referee import Referee, ScoreReport
from .rounds import RoundSetup


class KinematicWorld:
    """Parts at slot centres (or anywhere), a robot position, a set of held parts, a clock in seconds.

    ``teleport_delay``: control cycles between the factory asking for a teleport and the part's position showing
    it. 0 (the default): applied at the end of the same cycle, so the factory's next step sees the part at its
    output; n: applied at the end of the n-th cycle after, as the real SimTwo does through the referee's bridge
    (a few cycles; the factory copes, see ``TELEPORT_GRACE``); None: never applied (a lost teleport).
    ``teleports`` records every teleport the factory asked for, with the time it asked, applied or not;
    ``in_flight`` holds those still to be applied, with the cycles until they are.
    """

    def __init__(self, field: Field, setup: RoundSetup, *, dt: float = 0.04, robot_xy=(-0.725, -0.4),
                 teleport_delay: int | None = 0, **factory_kw):
        if teleport_delay is not None and (not isinstance(teleport_delay, int) or teleport_delay < 0):
            raise ConfigError(f"teleport_delay must be a number of cycles >= 0 or None, got {teleport_delay!r}")
        self.field = field
        self.factory = Factory(field, setup, **factory_kw)
        self.referee = Referee(self.factory)
        self.dt = dt
        self.t = 0.0
        self.robot_xy = tuple(robot_xy)
        self.part_xy: dict[int, tuple[float, float]] = {pid: slot.xy for pid, _, slot in self.factory.initial_parts()}
        self.held: set[int] = set()
        self.teleport_delay = teleport_delay
        self.teleports: list[tuple[float, Teleport]] = []
        self.in_flight: list[tuple[int, Teleport]] = []  # (cycles until applied, teleport); never applied: not kept

    def start(self) -> None:
        self.factory.start(self.t)

    def slot(self, zone: str, number: int) -> Slot:
        return self.field.slot(zone, number)

    def pick(self, part_id: int) -> None:
        """The electromagnet takes the part (it stays where it is until placed; it is in no slot)."""
        self.held.add(part_id)
        self.step()

    def place(self, part_id: int, zone: str, number: int, offset=(0.0, 0.0), *, leave: bool = True) -> None:
        """Put the part at a slot centre (plus ``offset`` metres) and release it. With ``leave`` the robot
        then backs away far from every slot (to the start area), as a real robot must for a machine."""
        s = self.slot(zone, number)
        self.robot_xy = (s.xy[0], s.xy[1])  # the robot stands at the slot while dropping
        self.part_xy[part_id] = (s.xy[0] + offset[0], s.xy[1] + offset[1])
        self.held.discard(part_id)
        self.step()
        if leave:
            self.robot_xy = (-0.725, -0.4)

    def move_part(self, part_id: int, xy) -> None:
        self.part_xy[part_id] = (float(xy[0]), float(xy[1]))

    def step(self) -> list[Teleport]:
        """One control cycle: advance the clock by ``dt``, step the factory, apply the teleports that are due
        (see ``teleport_delay``). Returns the teleports the factory asked for in this cycle."""
        self.t = round(self.t + self.dt, 9)
        out = self.factory.step(self.t, dict(self.part_xy), self.robot_xy, set(self.held))
        due = [tp for left, tp in self.in_flight if left <= 1]  # asked for in an earlier cycle
        self.in_flight = [(left - 1, tp) for left, tp in self.in_flight if left > 1]
        for tp in out:
            self.teleports.append((self.t, tp))
            if self.teleport_delay == 0:
                due.append(tp)
            elif self.teleport_delay is not None:
                self.in_flight.append((self.teleport_delay, tp))
        for tp in due:  # moved even if a magnet took it meanwhile (it stays in held)
            self.part_xy[tp.part_id] = tp.slot.xy
        return out

    def advance(self, seconds: float) -> list[Teleport]:
        """Run cycles for ``seconds`` of simulation time; returns the teleports the factory asked for."""
        out = []
        n = max(1, round(seconds / self.dt))
        for _ in range(n):
            out.extend(self.step())
        return out

    def report(self) -> ScoreReport:
        return self.referee.report(self.t)
