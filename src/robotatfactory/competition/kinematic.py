"""A kinematic stand-in for the simulator's side of the factory: parts are points, the robot is a point,
picking and placing are instant. It steps a :class:`Factory` exactly as the simulator does and applies its
teleports. For tests, scripted demonstrations and planners that need the factory without physics.

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

from ..field.model import Field, Slot
from .factory import Factory, Teleport
from .referee import Referee, ScoreReport
from .rounds import RoundSetup


class KinematicWorld:
    """Parts at slot centres (or anywhere), a robot position, a set of held parts, a clock in seconds."""

    def __init__(self, field: Field, setup: RoundSetup, *, dt: float = 0.04, robot_xy=(-0.725, -0.4), **factory_kw):
        self.field = field
        self.factory = Factory(field, setup, **factory_kw)
        self.referee = Referee(self.factory)
        self.dt = dt
        self.t = 0.0
        self.robot_xy = tuple(robot_xy)
        self.part_xy: dict[int, tuple[float, float]] = {pid: slot.xy for pid, _, slot in self.factory.initial_parts()}
        self.held: set[int] = set()
        self.teleports: list[tuple[float, Teleport]] = []

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
        """One control cycle: advance the clock by ``dt``, step the factory, apply its teleports."""
        self.t = round(self.t + self.dt, 9)
        out = self.factory.step(self.t, dict(self.part_xy), self.robot_xy, set(self.held))
        for tp in out:
            self.part_xy[tp.part_id] = tp.slot.xy
            self.teleports.append((self.t, tp))
        return out

    def advance(self, seconds: float) -> list[Teleport]:
        """Run cycles for ``seconds`` of simulation time; returns the teleports that happened."""
        out = []
        n = max(1, round(seconds / self.dt))
        for _ in range(n):
            out.extend(self.step())
        return out

    def report(self) -> ScoreReport:
        return self.referee.report(self.t)
