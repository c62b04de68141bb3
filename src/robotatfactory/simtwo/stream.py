"""Sequence bookkeeping of the SensorFrame stream: one sender, gaps, duplicates, reordering, restarts, forged
frames; rates and counters.

Plain Python, no ROS, no I/O: the bridge feeds every decoded frame (``Seq``, ``Tms``, encoder totals) with its
arrival time (a monotonic wall clock, seconds) and publishes only the frames the tracker accepts. See
docs/protocol.md, "Losing nothing, detecting everything", and docs/reliability.md.

**One sender** (:class:`SourceGate`): the stream belongs to one source address (host, port): the configured
one, or the first whose frames form a *consistent chain* (below). Datagrams from any other source are dropped
and counted by source; another source takes over only after the bound one has been silent for
``takeover_after`` seconds, and again only with a consistent chain.

**No single datagram poisons the state** (:class:`StreamTracker`), for a frame ``seq`` when the last accepted
one had ``last`` (and ``Tms`` ``last_t``):

* ``seq == last + 1``: the next frame (``NEXT``).
* ``seq > last + 1``: accepted; ``seq - last - 1`` frames were lost (``GAP``). Ticks are not lost: odometry
  differences the cumulative totals.
* ... unless ``seq`` or ``Tms`` is more than ``max_jump`` cycles ahead: such a frame is ``HELD`` (not applied)
  until ``confirm`` frames in a row form a consistent chain with it; then it is a ``GAP``.
* ``seq == last`` and the same ``Tms``: a duplicate, dropped (``DUPLICATE``).
* ``seq < last`` with ``Tms`` not ahead: an old frame arriving late, dropped (``STALE``).
* A restart (``Tms`` back) is never decided on one datagram: ``confirm`` frames in a row must form a
  consistent chain with ``Tms`` behind ``last_t`` (``RESTART``); odometry then counts from zero when the
  chain starts where a restarted stream starts (``Seq`` within ``restart_max_seq`` of 0 and ``Tms`` no more
  than that many cycles). Until confirmed, such frames are ``STALE`` (behind) or ``HELD`` (ahead).
* Odometry totals that move by more ticks than a wheel can turn in the elapsed simulation time
  (``max_ticks_per_s``) are rejected (``IMPLAUSIBLE``), state unchanged.

A *consistent chain*: each frame's ``Seq`` is 1..``reorder_window`` past the previous one and its ``Tms`` moved
by the same number of control periods (within a quarter of a period). A simulator's stream always is one; random or
forged datagrams practically never are.

Every frame from the bound source (accepted or not) is answered by the bridge, so a lockstep simulator
never stalls.
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
    HELD = "held"  # dropped for now: a jump (far ahead, or clock back with Seq ahead) not yet confirmed
    IMPLAUSIBLE = "implausible"  # dropped: encoder totals moved more than the wheels can turn

    @property
    def accepted(self) -> bool:
        return self in (Verdict.FIRST, Verdict.NEXT, Verdict.GAP, Verdict.RESTART)


#: Reasons a datagram is rejected before it is a SensorFrame (counted, logged rate-limited, not answered).
REJECT_KINDS = ("malformed", "foreign_source", "foreign_protocol", "oversized")


def chain_consistent(prev: tuple[int, int], cur: tuple[int, int], period_ms: int, window: int) -> bool:
    """True when frame ``cur`` = (seq, tms) can follow ``prev`` in one simulator's stream: Seq 1..window
    ahead and Tms ahead by as many control periods (within a quarter of a period: SimTwo's script and
    ``raf sim`` add exactly one period per cycle)."""
    ds, dt = cur[0] - prev[0], cur[1] - prev[1]
    return 1 <= ds <= window and abs(dt - ds * period_ms) <= max(1.0, period_ms / 4)


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
    #: for RESTART or a confirmed jump: the frames of the chain before this one (dropped at the time)
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
    held: int = 0  # frames held as unconfirmed jumps (forged, or a stream change not yet confirmed)
    jumps_confirmed: int = 0  # held jumps ahead that further frames confirmed (accepted as a GAP)
    implausible: int = 0  # frames whose encoder totals moved more than the wheels can turn
    rejected: dict = field(default_factory=lambda: {k: 0 for k in REJECT_KINDS})

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    def as_dict(self) -> dict:
        d = {k: getattr(self, k) for k in ("received", "accepted", "lost", "gaps", "duplicates", "stale",
                                           "restarts", "held", "jumps_confirmed", "implausible")}
        d.update({f"rejected_{k}": v for k, v in self.rejected.items()})
        return d


class StreamTracker:
    """Classifies each SensorFrame of one simulator stream (see the module docstring for the rules).

    ``reorder_window``: how far (frames) a chain may skip, and how far behind a late frame still counts as
    merely stale; ``restart_confirm``: frames in a consistent chain needed to confirm a restart or a jump;
    ``max_jump``: cycles ahead (Seq, or Tms in control periods) beyond which a frame is held;
    ``period_ms``: the control period; ``max_ticks_per_s``: the fastest a wheel's encoder can count (None:
    no check); ``restart_max_seq``: a chain starting at or below this Seq (and Tms) is a stream from zero.
    """

    def __init__(self, reorder_window: int = 25, restart_confirm: int = 3, max_jump: int = 250,
                 period_ms: int = 40, max_ticks_per_s: float | None = None, restart_max_seq: int | None = None):
        if reorder_window < 1 or restart_confirm < 1 or max_jump < 1 or period_ms < 1:
            raise ValueError("reorder_window, restart_confirm, max_jump and period_ms must be >= 1")
        self.reorder_window = reorder_window
        self.restart_confirm = restart_confirm
        self.max_jump = max_jump
        self.period_ms = period_ms
        self.max_ticks_per_s = max_ticks_per_s
        self.restart_max_seq = reorder_window if restart_max_seq is None else restart_max_seq
        self.counters = StreamCounters()
        self.last_seq: int | None = None
        self.last_time_ms: int | None = None
        self.last_totals: tuple[int, int] | None = None
        self.last_arrival: float | None = None
        self._run: list[tuple[int, int]] = []  # candidate chain: (seq, tms) of frames not accepted, in a row
        self._run_kinds: list[str] = []  # what each was counted as ("stale" or "held")

    def reset(self) -> None:
        """Forget the stream (the next frame is FIRST); counters are kept."""
        self.last_seq = self.last_time_ms = self.last_arrival = self.last_totals = None
        self._run, self._run_kinds = [], []

    def reject(self, kind: str) -> None:
        """Count a datagram that did not decode into a frame of this stream."""
        if kind not in self.counters.rejected:
            raise ValueError(f"unknown reject kind {kind!r}; one of {REJECT_KINDS}")
        self.counters.rejected[kind] += 1

    def restart_like(self, seq: int, time_ms: int) -> bool:
        """A frame where a freshly (re)started simulator's stream is: Seq near 0 and Tms small."""
        n = self.restart_max_seq
        return 0 <= seq <= n and 0 <= time_ms <= (n + 1) * self.period_ms + self.period_ms // 2

    def offer(self, seq: int, time_ms: int, arrival: float | None = None,
              totals: tuple[int, int] | None = None) -> Event:
        """Classify one decoded frame and update the state; ``arrival`` in seconds (monotonic); ``totals``
        the frame's cumulative encoder counts (left, right), checked against ``max_ticks_per_s``."""
        c = self.counters
        c.received += 1
        if arrival is None:
            arrival = time.monotonic()
        last, last_t = self.last_seq, self.last_time_ms
        if last is None:
            return self._accept(Event(Verdict.FIRST, seq, time_ms, from_zero=self.restart_like(seq, time_ms)
                                      and seq == 0), arrival, totals)
        if seq == last and time_ms == last_t:
            c.duplicates += 1
            return Event(Verdict.DUPLICATE, seq, time_ms)
        if seq > last and time_ms >= last_t:
            far = seq - last > self.max_jump or time_ms - last_t > self.max_jump * self.period_ms
            if not far:
                if not self._plausible(time_ms, totals):
                    c.implausible += 1
                    return Event(Verdict.IMPLAUSIBLE, seq, time_ms)
                lost = seq - last - 1
                if lost:
                    c.lost += lost
                    c.gaps += 1
                    return self._accept(Event(Verdict.GAP, seq, time_ms, lost=lost), arrival, totals)
                return self._accept(Event(Verdict.NEXT, seq, time_ms), arrival, totals)
        # not the continuation of the stream: an old frame, a jump, or the start of another stream
        kind = "stale" if (seq <= last and time_ms <= last_t and last - seq <= self.reorder_window) else "held"
        run, kinds = self._run, self._run_kinds
        if run and chain_consistent(run[-1], (seq, time_ms), self.period_ms, self.reorder_window):
            run.append((seq, time_ms))
            kinds.append(kind)
        else:
            run[:], kinds[:] = [(seq, time_ms)], [kind]
        if len(run) >= self.restart_confirm:
            n = len(run)
            for k in kinds[:-1]:  # they were counted as dropped when they came; they belonged to the new stream
                setattr(c, k, getattr(c, k) - 1)
            start = run[0]
            if time_ms < last_t or seq <= last:  # the clock or the sequence went back: the simulator restarted
                c.restarts += 1
                return self._accept(Event(Verdict.RESTART, seq, time_ms, from_zero=self.restart_like(*start),
                                          run_length=n), arrival, totals)
            # a jump ahead, confirmed by the frames after it (e.g. a long outage); the chain's earlier frames
            # were not applied: they count as lost (their ticks are in this frame's cumulative totals)
            c.jumps_confirmed += 1
            lost = seq - last - 1
            c.lost += lost
            c.gaps += 1
            return self._accept(Event(Verdict.GAP, seq, time_ms, lost=lost, run_length=n), arrival, totals)
        setattr(c, kind, getattr(c, kind) + 1)
        return Event(Verdict.STALE if kind == "stale" else Verdict.HELD, seq, time_ms)

    def _plausible(self, time_ms: int, totals) -> bool:
        if self.max_ticks_per_s is None or totals is None or self.last_totals is None:
            return True
        limit = self.max_ticks_per_s * max(0, time_ms - self.last_time_ms) / 1000 + 2  # +-1 tick quantisation
        return all(abs(a - b) <= limit for a, b in zip(totals, self.last_totals))

    def _accept(self, ev: Event, arrival: float, totals=None) -> Event:
        self.counters.accepted += 1
        self.last_seq, self.last_time_ms, self.last_arrival = ev.seq, ev.time_ms, arrival
        self.last_totals = None if totals is None else (int(totals[0]), int(totals[1]))
        self._run, self._run_kinds = [], []
        return ev

    def staleness(self, now: float | None = None) -> float | None:
        """Seconds (wall) since the last accepted frame, None before the first one."""
        if self.last_arrival is None:
            return None
        return (time.monotonic() if now is None else now) - self.last_arrival


def source_key(addr) -> str:
    """``host:port`` of a source address."""
    return f"{addr[0]}:{addr[1]}"


class SourceGate:
    """Which source (host, port) the stream belongs to; counts everything else by source.

    ``source``: the configured (host, port), or None to bind the first source whose frames form a consistent
    chain of ``confirm`` frames. ``takeover_after``: wall seconds the bound source must have been silent
    before another may take over (again with a consistent chain). Times are monotonic seconds.
    """

    MAX_SOURCES = 64  # distinct foreign sources counted by name; the rest under "other"

    def __init__(self, source: tuple[str, int] | None = None, takeover_after: float = 2.0, confirm: int = 3,
                 period_ms: int = 40, window: int = 25):
        self.configured = source is not None
        self.bound: tuple[str, int] | None = tuple(source) if source is not None else None
        self.takeover_after = takeover_after
        self.confirm = max(1, confirm)
        self.period_ms = period_ms
        self.window = window
        self.last_seen: float | None = None  # arrival of the last frame from the bound source
        self.foreign: dict[str, int] = {}
        self.takeovers = 0
        self.binds = 0
        self._cand: dict[tuple, list] = {}  # source -> chain [(seq, tms, payload)]
        #: (source, ms per Seq) of the last candidate whose Seq ran on but whose Tms did not follow the control
        #: period: a simulator whose script period differs from ~geometry/control_period never binds
        self.period_mismatch: tuple[tuple, float] | None = None

    def is_bound(self, addr) -> bool:
        return self.bound is not None and (addr[0], addr[1]) == self.bound

    def silent_for(self, now: float) -> float | None:
        return None if self.last_seen is None else now - self.last_seen

    def open_to(self, addr, now: float) -> bool:
        """May a frame from ``addr`` be considered at all (bound source, or binding/takeover possible)?"""
        if self.is_bound(addr):
            return True
        if self.bound is None:
            return True
        if self.configured:
            return False
        s = self.silent_for(now)
        return s is None or s >= self.takeover_after

    def seen(self, now: float) -> None:
        """A frame from the bound source arrived."""
        self.last_seen = now

    def count_foreign(self, addr) -> None:
        key = source_key(addr)
        if key not in self.foreign and len(self.foreign) >= self.MAX_SOURCES:
            key = "other"
        self.foreign[key] = self.foreign.get(key, 0) + 1

    @property
    def foreign_total(self) -> int:
        return sum(self.foreign.values())

    def candidate(self, addr, seq: int, time_ms: int, payload, now: float) -> list | None:
        """A decoded frame from an unbound source that may bind: returns the chain's payloads (oldest first)
        when it confirms the source (which is then bound), else None."""
        key = (addr[0], addr[1])
        if self.configured:
            return None
        chain = self._cand.get(key)
        if chain and chain_consistent(chain[-1][:2], (seq, time_ms), self.period_ms, self.window):
            chain.append((seq, time_ms, payload))
        else:
            if chain and 1 <= seq - chain[-1][0] <= self.window and time_ms > chain[-1][1]:
                self.period_mismatch = (key, (time_ms - chain[-1][1]) / (seq - chain[-1][0]))
            if len(self._cand) >= self.MAX_SOURCES:  # a flood of sources: forget the oldest candidates
                self._cand.pop(next(iter(self._cand)))
            chain = self._cand[key] = [(seq, time_ms, payload)]
        if len(chain) < self.confirm:
            return None
        if self.bound is not None:
            self.takeovers += 1
        self.binds += 1
        self.bound = key
        self.last_seen = now
        self._cand.clear()
        return [p for _, _, p in chain]


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


OK, WARN, ERROR = 0, 1, 2  # the levels of diagnostic_msgs/DiagnosticStatus


def stream_health(now: dict, before: dict, staleness: float | None, gate: SourceGate, port: int,
                  stale_warn: float, stale_error: float, loss_warn: float = 0.05) -> tuple[int, str]:
    """Level (OK/WARN/ERROR) and a message saying what to check, from the tracker's counters (``as_dict``)
    now and at the previous report, the wall seconds since the last accepted frame and the source gate."""
    d = {k: now.get(k, 0) - before.get(k, 0) for k in now}
    bound = source_key(gate.bound) if gate.bound else None
    if staleness is None:
        where = f"from {bound}" if bound else "from any sender yet"
        return WARN, (f"waiting for SensorFrames on udp port {port} ({where}): is the simulator running, and "
                      "sending to this machine and port?")
    if staleness > stale_error:
        return ERROR, (f"stale: no SensorFrame from {bound} for {staleness:.1f} s: simulator stopped, paused or "
                       "restarted on another port (another sender takes over after ~stream/takeover_after s)")
    if staleness > stale_warn:
        return WARN, f"stale: no SensorFrame from {bound} for {staleness:.1f} s: simulator paused or overloaded?"
    issues, level = [], OK
    if d.get("rejected_foreign_source", 0):
        top = ", ".join(f"{k} ({v})" for k, v in sorted(gate.foreign.items(), key=lambda kv: -kv[1])[:3])
        issues.append(f"{d['rejected_foreign_source']} datagram(s) from other senders ({top}): a second simulator "
                      f"or program sending to udp port {port}? give each robot its own port")
    if d.get("held", 0) or d.get("implausible", 0):
        issues.append(f"{d.get('held', 0)} frame(s) held as unconfirmed jumps, {d.get('implausible', 0)} with "
                      f"impossible encoder counts, from {bound}: corrupt or forged datagrams")
    if d.get("restarts", 0):
        issues.append(f"the simulator restarted {d['restarts']} time(s): odometry was reset")
    if d.get("jumps_confirmed", 0):
        issues.append(f"the stream jumped ahead {d['jumps_confirmed']} time(s): a long outage?")
    bad = sum(d.get(k, 0) for k in ("rejected_malformed", "rejected_foreign_protocol", "rejected_oversized"))
    if bad:
        issues.append(f"{bad} malformed, oversized or non-RAF datagram(s) from {bound}: protocol version "
                      "mismatch between the script and the bridge?")
    got = d.get("accepted", 0) + d.get("lost", 0)
    if got and d.get("lost", 0) / got > loss_warn:
        issues.append(f"{100 * d['lost'] / got:.0f} % of frames lost since the last report: network, or CPU load "
                      "on the simulator's machine (ticks are kept)")
    if d.get("duplicates", 0) and d.get("duplicates", 0) / max(1, got) > loss_warn:
        issues.append(f"{d['duplicates']} duplicated frame(s): two copies of the script or a network loop?")
    if issues:
        level = WARN
    return level, ("receiving from " + str(bound) + ("; " + "; ".join(issues) if issues else ""))
