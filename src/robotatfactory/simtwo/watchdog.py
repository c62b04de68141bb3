"""The reply to each SensorFrame: the latest velocity command, unless it is too old in simulation time.

Plain Python, not thread-safe on its own (the bridge holds a lock around it).
"""
from __future__ import annotations

from dataclasses import dataclass

from .messages import Command


@dataclass
class CommandWatchdog:
    """Latest (V, W, magnet) with a watchdog: V = W = 0 once the velocity is older than ``timeout_s``.

    Ages are simulation milliseconds (``Tms``), so a simulator running slower or faster than real time
    does not trip it. A velocity set before the first frame (``now_ms`` None) counts as fresh at the next one.
    """

    timeout_s: float
    v: float = 0.0
    w: float = 0.0
    magnet: bool = False
    have_velocity: bool = False
    velocity_ms: int | None = None  # Tms when the last velocity arrived
    stopping: bool = False  # the watchdog is replacing the velocity by zero
    stops: int = 0  # times the watchdog started stopping the robot

    def set_velocity(self, v: float, w: float, now_ms: int | None) -> None:
        self.v, self.w = v, w
        self.have_velocity = True
        self.velocity_ms = now_ms

    def reply(self, seq: int, time_ms: int) -> tuple[Command, bool]:
        """The Command answering frame ``seq`` at ``time_ms``, and whether the watchdog just tripped."""
        fresh, tripped = False, False
        if self.have_velocity:
            if self.velocity_ms is None:
                self.velocity_ms = time_ms
            fresh = 0 <= self.age_ms(time_ms) <= self.timeout_s * 1000
            if not fresh and not self.stopping:
                self.stopping, tripped = True, True
                self.stops += 1
            elif fresh:
                self.stopping = False
        v, w = (self.v, self.w) if fresh else (0.0, 0.0)
        return Command(v, w, self.magnet, seq), tripped

    def age_ms(self, time_ms: int | None) -> int | None:
        """Age of the velocity at ``time_ms`` (None when unknown)."""
        if time_ms is None or self.velocity_ms is None:
            return None
        return time_ms - self.velocity_ms

    def reset(self) -> None:
        """Forget every command (the simulator restarted): stop, magnet off."""
        stops = self.stops
        self.__init__(self.timeout_s)
        self.stops = stops
