"""Sequence bookkeeping of the SensorFrame stream: gaps, duplicates, reordering, restarts; rates and counters.

Plain Python, no ROS, no I/O: the bridge feeds every decoded frame (``Seq``, ``Tms``) with its arrival time
(a monotonic wall clock, seconds) and publishes only the frames the tracker accepts. See docs/protocol.md,
"Losing nothing, detecting everything".

Rules, for a frame with sequence number ``seq`` when the last accepted one had ``last``:

* ``seq == last + 1``: the next frame (``NEXT``).
* ``seq > last + 1``: accepted; ``seq - last - 1`` frames were lost (``GAP``). Ticks are not lost: odometry
  differences the cumulative totals.
* ``seq == last`` and the same ``Tms``: a duplicate, dropped (``DUPLICATE``).
* ``seq < last`` (or ``seq == last`` with another ``Tms``): an old frame arriving late, dropped
  (``STALE``), unless it is a restart: ``Tms`` went backwards AND either ``last - seq`` exceeds
  ``reorder_window`` (a simulator that restarted after a while), or ``restart_confirm`` consecutive stale
  frames form a run of consecutive sequence numbers with increasing ``Tms`` (a simulator restarted soon after
  starting, when a single old frame and a new stream cannot be told apart from one datagram). Then the
  stream starts again (``RESTART``): odometry, clock and camera stamping are reset by the bridge.
* ``seq`` ahead but ``Tms`` behind the last accepted frame: the clock cannot go backwards within one run,
  so this is a restart too (the simulator restarted while its frames were not reaching us).

Every frame (accepted or not) is answered by the bridge, so a lockstep simulator never stalls.
"""
from __future__ import annotations

import enum
import time
from collections import deque
from dataclasses import dataclass, field


class Verdict(enum.Enum):
    FIRST = "first"  # the first frame of a stream (start of the bridge, or after a reset)
    NEXT = "next"
    GAP = "gap"  # accepted; some frames before it were lost
    RESTART = "restart"  # accepted; the simulator restarted, state must be reset
    DUPLICATE = "duplicate"  # dropped
    STALE = "stale"  # dropped: older than the last accepted frame (out of order)

    @property
    def accepted(self) -> bool:
        return self in (Verdict.FIRST, Verdict.NEXT, Verdict.GAP, Verdict.RESTART)


#: Reasons a datagram is rejected before it is a SensorFrame (counted, logged rate-limited, not answered).
REJECT_KINDS = ("malformed", "foreign_source", "foreign_protocol", "oversized")


@dataclass(frozen=True)
class Event:
    """What the tracker decided about one frame."""

    verdict: Verdict
    seq: int
    time_ms: int
    lost: int = 0  # frames lost just before this one (GAP)
    #: for FIRST/RESTART: the stream is known to start at Seq 0 here, so cumulative totals count from zero
    #: (odometry integrates the very first cycles); otherwise the frame's own totals are the baseline.
    from_zero: bool = False
    #: for RESTART confirmed by a run: the frames of the run before this one (dropped as STALE at the time)
    run_length: int = 1

    @property
    def accepted(self) -> bool:
        return self.verdict.accepted


@dataclass
class StreamCounters:
    """Totals since the bridge started (never reset by a simulator restart)."""

    received: int = 0  # decoded frames offered to the tracker
    accepted: int = 0
    lost: int = 0  # frames missing from Seq gaps
    gaps: int = 0  # gap events
    duplicates: int = 0
    stale: int = 0  # out-of-order frames dropped
    restarts: int = 0
    rejected: dict = field(default_factory=lambda: {k: 0 for k in REJECT_KINDS})

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("received", "accepted", "lost", "gaps", "duplicates", "stale", "restarts")}
        d.update({f"rejected_{k}": v for k, v in self.rejected.items()})
        return d


class StreamTracker:
    """Classifies each SensorFrame of one simulator stream (see the module docstring for the rules)."""

    def __init__(self, reorder_window: int = 25, restart_confirm: int = 3):
        if reorder_window < 1 or restart_confirm < 1:
            raise ValueError("reorder_window and restart_confirm must be >= 1")
        self.reorder_window = reorder_window
        self.restart_confirm = restart_confirm
        self.counters = StreamCounters()
        self.last_seq: int | None = None
        self.last_time_ms: int | None = None
        self.last_arrival: float | None = None
        self._run: list[tuple[int, int]] = []  # candidate restart run: (seq, tms) of consecutive stale frames

    def reset(self) -> None:
        """Forget the stream (the next frame is FIRST); counters are kept."""
        self.last_seq = self.last_time_ms = self.last_arrival = None
        self._run = []

    def reject(self, kind: str) -> None:
        """Count a datagram that did not decode into a frame of this stream."""
        if kind not in self.counters.rejected:
            raise ValueError(f"unknown reject kind {kind!r}; one of {REJECT_KINDS}")
        self.counters.rejected[kind] += 1

    def offer(self, seq: int, time_ms: int, arrival: float | None = None) -> Event:
        """Classify one decoded frame and update the state; ``arrival`` in seconds (monotonic)."""
        c = self.counters
        c.received += 1
        if arrival is None:
            arrival = time.monotonic()
        last, last_t = self.last_seq, self.last_time_ms
        if last is None:
            return self._accept(Event(Verdict.FIRST, seq, time_ms, from_zero=(seq == 0)), arrival)
        if seq > last:
            if time_ms < last_t:
                return self._restart(seq, time_ms, arrival, run_length=1)
            lost = seq - last - 1
            if lost:
                c.lost += lost
                c.gaps += 1
                return self._accept(Event(Verdict.GAP, seq, time_ms, lost=lost), arrival)
            return self._accept(Event(Verdict.NEXT, seq, time_ms), arrival)
        if seq == last and time_ms == last_t:
            c.duplicates += 1
            return Event(Verdict.DUPLICATE, seq, time_ms)
        # behind the last accepted frame
        if time_ms < last_t and last - seq > self.reorder_window:
            return self._restart(seq, time_ms, arrival, run_length=1)
        run = self._run
        if run and seq == run[-1][0] + 1 and time_ms > run[-1][1]:
            run.append((seq, time_ms))
        else:
            run[:] = [(seq, time_ms)]
        if len(run) >= self.restart_confirm and time_ms < last_t:
            return self._restart(seq, time_ms, arrival, run_length=len(run), run_start=run[0][0])
        c.stale += 1
        return Event(Verdict.STALE, seq, time_ms)

    def _restart(self, seq, time_ms, arrival, run_length, run_start=None) -> Event:
        self.counters.restarts += 1
        if run_length > 1:
            # the run's earlier frames were counted stale when they came; they belonged to the new stream
            self.counters.stale -= run_length - 1
        start = seq if run_start is None else run_start
        return self._accept(Event(Verdict.RESTART, seq, time_ms, from_zero=(start == 0), run_length=run_length),
                            arrival)

    def _accept(self, ev: Event, arrival: float) -> Event:
        self.counters.accepted += 1
        self.last_seq, self.last_time_ms, self.last_arrival = ev.seq, ev.time_ms, arrival
        self._run = []
        return ev

    def staleness(self, now: float | None = None) -> float | None:
        """Seconds (wall) since the last accepted frame, None before the first one."""
        if self.last_arrival is None:
            return None
        return (time.monotonic() if now is None else now) - self.last_arrival


class RateMeter:
    """Events per second over a sliding wall-clock window, and the time since the last event."""

    def __init__(self, window: float = 2.0, maxlen: int = 20000):
        self.window = window
        self._t: deque[float] = deque(maxlen=maxlen)
        self.count = 0

    def tick(self, now: float | None = None) -> None:
        self._t.append(time.monotonic() if now is None else now)
        self.count += 1

    def rate(self, now: float | None = None) -> float:
        """Mean rate over the window ending now (0 when fewer than two events are in it)."""
        now = time.monotonic() if now is None else now
        t = self._t
        while t and t[0] < now - self.window:
            t.popleft()
        if len(t) < 2:
            return 0.0
        span = max(now - t[0], t[-1] - t[0])
        return (len(t) - 1) / span if span > 0 else 0.0

    @property
    def last(self) -> float | None:
        return self._t[-1] if self._t else None

    def age(self, now: float | None = None) -> float | None:
        if not self._t:
            return None
        return (time.monotonic() if now is None else now) - self._t[-1]


class LogLimiter:
    """At most one message per ``period`` wall seconds per key; says how many were suppressed in between."""

    def __init__(self, period: float = 5.0):
        self.period = period
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def __call__(self, key: str, now: float | None = None) -> str | None:
        """None to stay quiet, else a suffix (possibly empty) to append to the message being logged."""
        now = time.monotonic() if now is None else now
        t = self._last.get(key)
        if t is not None and now - t < self.period:
            self._suppressed[key] = self._suppressed.get(key, 0) + 1
            return None
        self._last[key] = now
        n = self._suppressed.pop(key, 0)
        return f" ({n} more like this in the last {now - t:.0f} s)" if n and t is not None else ""
