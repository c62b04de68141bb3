"""A referee for a simulator that only reports where things are: the real SimTwo.

The stand-in (``raf sim``) runs the factory and the referee inside its own loop: it knows which part its
magnet holds and moves parts itself. SimTwo knows none of this; its scene script (``simtwo/control.pas``)
reports, every control cycle, the robot's and the parts' ground truth (the SensorFrame's ``X Y Theta`` and
optional ``Parts`` labels, docs/protocol.md) and the magnet as applied. :class:`LiveReferee` turns those
cycles into the same :class:`~.factory.Factory` and :class:`~.referee.Referee` as the stand-in's:

* **the start**: the run starts ``start_after`` s of simulation time after the first cycle (the organiser's
  signal; the factory-state server answers STOP until then); with ``wait_ready``, not before the caller says
  the robot is ready (:meth:`LiveReferee.set_ready`: a referee waits for a team's robot to be localized
  before the start), or ``ready_timeout`` s after the first cycle at the latest;
* **held**: SimTwo does not say which part the magnet holds; a part counts as held while the magnet is on
  and the part's centre is where a held part sits, ahead of the magnet's face (:meth:`LiveReferee.held`);
* **the machines**: the factory's teleports (a processed part moved from a machine's input to its output)
  are returned to the caller, which applies them in the simulator (on SimTwo through the bridge's
  ``sim/place_part``: SimTwo moves the part, but cannot recolour it; the factory keeps the new type);
* **the trace**: with ``trace`` every cycle is written in the stand-in's trace format (``raf sim --trace``,
  :mod:`robotatfactory.sim.trace` reads it), so ``raf experiment competition`` measures runs on either
  simulator the same way; ``cmd`` there is the last command the caller saw, not the one SimTwo applied.

Plain Python: the ROS node (``raf referee``, :mod:`robotatfactory.ros.referee_node`) feeds it.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import IO

from ..errors import ConfigError
from .factory import Factory, Teleport
from .referee import Referee, ScoreReport
from .rounds import RoundSetup

TRACE_VERSION = 1  # robotatfactory.sim.trace's format
#: a held part's centre may be this far (m) from where it sits when held flat against the magnet's face
HELD_REACH = 0.03
#: s of simulation time after the first cycle the run waits at most for the robot to be ready (``wait_ready``)
READY_TIMEOUT = 60.0


class LiveReferee:
    """Scores a run from reported cycles. See the module docstring."""

    def __init__(self, field, robot, setup: RoundSetup, *, start_after: float = 3.0,
                 trace: str | Path | None = None, seed: int | None = None, held_reach: float = HELD_REACH,
                 wait_ready: bool = False, ready_timeout: float = READY_TIMEOUT):
        if not (math.isfinite(start_after) and start_after >= 0):
            raise ConfigError(f"start_after must be >= 0 simulation seconds, got {start_after!r}")
        if not (math.isfinite(ready_timeout) and ready_timeout >= 0):
            raise ConfigError(f"ready_timeout must be >= 0 simulation seconds, got {ready_timeout!r}")
        if not (math.isfinite(held_reach) and held_reach > 0):
            raise ConfigError(f"held_reach must be a distance > 0 in metres, got {held_reach!r}")
        self.field, self.robot, self.setup = field, robot, setup
        self.factory = Factory(field, setup)
        self.referee = Referee(self.factory)
        self.start_after = float(start_after)
        self.held_reach = float(held_reach)
        self.ready = not wait_ready  # the robot is ready (set_ready), or nobody asked to wait for it
        self.ready_timeout = float(ready_timeout)
        self.ready_at: float | None = None  # simulation time of set_ready
        self.started_unready = False  # the run started at the timeout, the robot never said it was ready
        # where a held part's centre sits in the robot's frame: its plate (2 mm, within the reach) against
        # the magnet's face
        self.held_x = float(robot.electromagnet["x"]) + field.part.depth / 2
        self.ids = self.factory.part_ids
        self.t0: float | None = None
        self.t: float | None = None
        self.cycles = 0
        self.max_at: float | None = None
        self._trace: IO[str] | None = None
        if trace is not None:
            try:
                self._trace = open(trace, "w", encoding="utf-8")
            except OSError as e:
                raise ConfigError(f"trace {trace}: cannot write it: {e.strerror}") from None
            self._write({"trace": TRACE_VERSION, "control_period": robot.control_period, "robot": robot.name,
                         "parts": {str(p): self.factory.part_type(p).letter for p in self.ids},
                         "round": setup.round_no, "seed": seed, "simulator": "reported (raf referee)"})

    def set_ready(self) -> None:
        """The robot is ready (its localization has a pose): the run may start (``wait_ready``)."""
        if not self.ready:
            self.ready, self.ready_at = True, self.t

    # ------------------------------------------------------------------------------------------ a cycle
    def held(self, pose, parts: dict[int, tuple[float, float, float]], magnet: bool) -> int | None:
        """The part the magnet holds: with the magnet on, the part nearest to where a held part sits, if
        within ``held_reach``; None otherwise."""
        if not magnet:
            return None
        x, y, th = pose
        hx, hy = x + self.held_x * math.cos(th), y + self.held_x * math.sin(th)
        best, best_d = None, self.held_reach
        for pid, (px, py, _) in parts.items():
            d = math.hypot(px - hx, py - hy)
            if d <= best_d:
                best, best_d = pid, d
        return best

    def cycle(self, t: float, seq: int, pose, parts, magnet: bool, contact: bool = False,
              enc=(0, 0), cmd=(0.0, 0.0, False)) -> list[Teleport]:
        """One reported control cycle at simulation time ``t``: ``pose`` (x, y, theta) of the robot, ``parts``
        the (x, y, theta) of part 1..N or {id: (x, y, theta)}, theta the plate's facing (SensorFrame.parts'
        heading less pi/2, :func:`~..simtwo.teleport.plate_facing`); ``magnet`` as applied.
        Starts the run when its time has come, steps the factory and writes the trace. Returns the
        teleports the simulator must apply."""
        t = float(t)
        if self.t0 is None:
            self.t0 = t
        self.t = t
        self.cycles += 1
        by_id = dict(parts) if isinstance(parts, dict) else {k: tuple(p) for k, p in enumerate(parts, start=1)}
        by_id = {pid: p for pid, p in by_id.items() if pid in self.ids}
        if not self.factory.started and t >= self.t0 + self.start_after:
            if self.ready or t >= self.t0 + max(self.ready_timeout, self.start_after):
                self.started_unready = not self.ready
                self.factory.start(t)
        held = self.held(pose, by_id, magnet)
        teleports = self.factory.step(t, {pid: (p[0], p[1]) for pid, p in by_id.items()}, (pose[0], pose[1]),
                                      () if held is None else (held,))
        if self._trace is not None:
            self._write({"t": round(t, 4), "seq": int(seq), "pose": [round(float(v), 5) for v in pose],
                         "held": held, "cmd": [round(float(cmd[0]), 4), round(float(cmd[1]), 4), bool(cmd[2])],
                         "contact": bool(contact), "enc": [int(enc[0]), int(enc[1])],
                         "parts": [[pid, *(round(float(v), 5) for v in p)] for pid, p in sorted(by_id.items())]})
        if self.factory.started:  # the maximum must stand: a part knocked out takes it back (referee.py)
            rep = self.report()
            if rep.points < rep.max_points:
                self.max_at = None
            elif self.max_at is None:
                self.max_at = t
        return teleports

    # ---------------------------------------------------------------------------------------- the score
    def report(self) -> ScoreReport:
        return self.referee.report(self.t if self.t is not None else 0.0)

    def max_held_for(self, seconds: float) -> bool:
        """True once the maximum score has stood for ``seconds`` of simulation time (without a point lost)."""
        return self.max_at is not None and self.t is not None and self.t - self.max_at >= seconds - 1e-9

    def over(self) -> bool:
        return self.t is not None and self.factory.over(self.t)

    def close(self) -> None:
        if self._trace is not None:
            self._trace.close()
            self._trace = None

    def _write(self, obj) -> None:
        self._trace.write(json.dumps(obj, separators=(",", ":")) + "\n")
        if self.cycles % 25 == 0:
            self._trace.flush()
