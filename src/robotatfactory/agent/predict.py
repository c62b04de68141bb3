"""Bring a pose estimate forward to when the next command will act.

The estimate is ``age`` seconds old when the controller uses it (the EKF's stamp, the transport, the control
timer), and the command it computes starts to act later still: on SimTwo and on the stand-in the bridge
answers each SensorFrame at once with the latest command, and the simulator runs a reply from the cycle
after the next, so a command published at the tick of frame n runs from frame n + 2 (80 ms; measured by
``raf experiment competition --stack full``, ``command_delay_median_s``). A turning robot moves a lot in
that time (3 rad/s x 120 ms = 0.36 rad). So the agent steers the pose at the moment its command will start
to act: the estimate brought to now at the measured speeds, then on through the commands already sent and
not yet run (:class:`InFlight`). Unicycle motion at constant body speeds, exact on arcs.
"""
from __future__ import annotations

from collections import deque

from ..localization.geometry import compose2, se2_exp


def extrapolate(pose: tuple[float, float, float], v: float, w: float, age: float) -> tuple[float, float, float]:
    """The pose (x, y, theta; m, rad) after ``age`` s at speeds (v, w); exact on the arc."""
    if age <= 0.0:
        return tuple(pose)
    return compose2(pose, se2_exp((v * age, 0.0, w * age)))


class InFlight:
    """The commands sent during the last ``latency`` seconds: they have not run yet, and will, one control
    ``period`` each, before the next command does. ``latency`` 0: nothing is in flight."""

    def __init__(self, latency: float, period: float):
        if latency < 0 or period <= 0:
            raise ValueError(f"latency {latency} must be >= 0 and period {period} > 0")
        self.latency, self.period = float(latency), float(period)
        self._sent: deque[tuple[float, float, float]] = deque()

    def sent(self, t: float, v: float, w: float) -> None:
        """The command (v m/s, w rad/s) published at time ``t`` (s)."""
        self._sent.append((t, v, w))
        while self._sent and self._sent[0][0] < t - self.latency + self.period / 2:  # has run by the next tick
            self._sent.popleft()

    def ahead(self, pose: tuple[float, float, float], now: float) -> tuple[float, float, float]:
        """``pose`` (the robot's pose now) carried through the commands in flight at ``now``: where it will be
        when a command published now starts to act."""
        if self.latency <= 0:
            return tuple(pose)
        n = max(0, round(self.latency / self.period))
        cmds = [c for c in self._sent if c[0] > now - self.latency - self.period / 2][-n:] if n else []
        # before there are enough (the start), the oldest known command stands in for the missing ones
        fill = [cmds[0]] * (n - len(cmds)) if cmds else []
        for _t, v, w in fill + cmds:
            pose = extrapolate(pose, v, w, self.period)
        return tuple(pose)
