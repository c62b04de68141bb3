"""Simulation time from the SensorFrame stream, and honest simulation-time stamps for camera frames.

Plain Python, no ROS, no I/O. Times: simulation time in integer milliseconds (``Tms``) or seconds; arrival
times in seconds of one monotonic wall clock shared by the UDP and the camera receivers (the bridge takes a
datagram's arrival from the kernel's receive timestamp, not from when a thread read it).

The camera problem. SimTwo's camera frames (ZMQ, 640x480 BGRA) carry no timestamp. The bridge stamps each
one with an estimate of the simulation time at which it was rendered, using only what any SimTwo user has:

1. the SensorFrame stream: ``Tms`` (end of each control cycle, period ``P`` = 40 ms) and its arrival times;
2. the camera frame's arrival time;
3. the camera's render-clock settings: render ticks every ``1/render_fps`` s of simulation time, one frame
   published every ``decimation`` ticks (60 FPS / 4 = 15 frames/s);
4. the ordering rule: a frame rendered at ``t_r`` is published after the SensorFrame of the cycle before
   and before the SensorFrame of the cycle whose end is the first cycle end ``>= t_r``; a simulator that
   renders during the cycle and publishes just before sending the cycle's SensorFrame (the stand-in does;
   so does a SimTwo script that sends right after the render) puts the two close together on the wall clock.

Method (``CameraStamper``), for a camera frame arriving at wall time ``a``:

* **Bracket: the nearest SensorFrame.** The frame is published just before its own cycle's SensorFrame, so
  it arrives close to it: shortly before it (UDP and ZMQ equally fast), or shortly after it (a 1.2 MB frame
  takes longer to deliver than a 3 KB datagram sent just after it: the SensorFrame *overtook* it). The
  frame is assigned to whichever of the SensorFrames just before (``T_prev``, arrived ``a_prev``) and just
  after (``T_next``) arrived nearer to it: ``t_r`` in ``(T_prev - P, T_prev]`` if ``a - a_prev`` is the
  smaller gap, else ``(T_next - P, T_next]``. This needs no latency threshold and holds in real time and in
  a fast lockstep run alike, as long as the frame's delivery takes less than half the wall time between
  two SensorFrames. The decision may have to wait for the next SensorFrame, but never longer than
  ``a - a_prev`` (after that the previous one is known to be nearer) nor than ``max_wait``.
  With ``rule="following"`` the frame is instead taken to belong to the cycle after the last SensorFrame
  received before it, ``(T_prev, T_prev + P]``, without waiting: right for a simulator that renders and
  publishes between control cycles at arbitrary moments (SimTwo's GUI loop renders the scene as it is, at a
  simulation time after the last script cycle), as long as delivery does not reorder the two streams.
* **Render grid.** Published frames sit on the ticks ``k / render_fps`` with ``k = phase (mod decimation)``.
  A 40 ms bracket holds two or three render ticks but (since ``P < decimation / render_fps`` = 66.7 ms) at
  most one tick of each phase. Each frame therefore allows a set of phases; over the last ``window`` frames
  (at least ``min_frames``) a phase allowed by all of them but one in eight, and by two frames more than any
  other phase, is locked: the frame's render tick is identified and the stamp is exact (``method =
  "grid"``, error 0). With the phase locked, the tick is taken from the two cycles around the
  bracket's SensorFrame (80 ms: at most two ticks of the phase, 66.7 ms apart), the one not used by an
  earlier frame; only when both are free (the earlier frame was lost) does the bracket choose. A bracket the
  grid corrects is counted (``rebracketed``).
* **Sequence.** Once a frame has its tick, the next frame's tick is that one plus ``decimation`` times
  (1 + the frames the receiver skipped in between, which the caller passes as ``skipped``): every
  published tick reaches the receiver, in order, so counting frames is exact while the receive queue does
  not overflow. Counting is what keeps stamps exact when the camera's delivery is delayed by load (a frame
  a whole cycle late on the wall clock has a wrong bracket, but its place in the sequence is right). The
  sequence is checked against the arrival times and dropped (``resyncs``: the tick is looked for again
  from the brackets) when its
  tick is later than the frame can have been rendered (after the cycle that follows the last SensorFrame
  received before it) or more than a cycle after its bracket, when the frame arrived more than
  ``max_delay`` wall seconds after the SensorFrame that followed the counted tick, when the brackets lock
  onto another phase, or when ``max_disagree`` frames in a row fall outside their brackets. A delay by load
  disturbs the brackets of a few frames in a row; a frame lost where the receiver cannot count it (or a
  render the simulator skipped) shifts every stamp that follows one grid step early until one of these
  checks fires (a few frames: ``tests/test_bridge_timing.py`` measures it).
* **Fallbacks.** With several phases left, the stamp is the middle of the remaining candidate ticks
  (``"grid-partial"``, error at most half their spread, <= 20 ms). Before ``min_frames`` frames, or when no
  phase is consistent with the recent frames (a render clock not locked to simulation time, as in SimTwo's
  wall-paced GUI), or with ``use_grid=False``, the stamp is the middle of the bracket (``"interval"``,
  error at most P/2 = 20 ms, when the bracket is right). The grid's bound assumes render ticks on
  simulation time; a free-running render clock can pass the consistency test by chance for a while, so
  set ``use_grid=False`` for such a simulator.

**Elapsed time (``rule="elapsed"``, the bridge's default: right for SimTwo and for ``raf sim``).** SimTwo
renders in its GUI loop (``sim/camera.py`` has the source references): the frame shows the end of a 17 ms
physics chunk, and leaves SimTwo right after the SensorFrames of the script calls in that chunk and before
the next one. Its render instant is no grid of simulation time, but the GUI runs simulation time in step
with the wall clock. So a frame arriving at ``a`` is placed after the last SensorFrame that arrived before it
(``T_i``, arrived ``a_i``) by the wall time between them, converted with the stream's real-time factor ``r``
(simulation seconds per wall second over the last ``rate_window`` seconds) and less the frame's transport
``latency``, and clamped to that SensorFrame's cycle: ``stamp = T_i + clamp((a - a_i - latency) * r, 0,
P)``. No waiting, no grid, no phase to learn. A frame that leaves just before its cycle's SensorFrame
(``raf sim``) and is overtaken by it lands on ``T_i`` itself (it was rendered in the cycle ending there);
one that is not lands at most a cycle after ``T_i``; either way within one cycle of its render time.
Frames delayed on their way by more than the time to the next SensorFrame are stamped later by about their
delay. A frame arriving more than 1.5 cycles (of the stream's wall time) after the last SensorFrame known
waits up to ``wait_overdue`` (0.3 s) for the next one (counted as ``waited``): on a loaded machine the
bridge may pass a SensorFrame on after the frame that followed it, which would otherwise be stamped a cycle
early (under a whole test suite's load on two cores, frames came 81 and 148 ms early with a shorter wait). Stamps count as ``elapsed``; clamped ones (the frame came later than a cycle after ``T_i``, by load
or a slow simulator) also as ``clamped``.

Stamps are kept strictly increasing; a frame that would break that is nudged 1 ms after the previous one
and counted (``conflicts``).
"""
from __future__ import annotations

import bisect
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from fractions import Fraction


RULES = ("elapsed", "following", "nearest")


def _fraction(x: float | int) -> Fraction:
    return Fraction(x).limit_denominator(100000) if isinstance(x, float) else Fraction(x)


@dataclass(frozen=True)
class StampEstimate:
    """Estimated render time of one camera frame."""

    stamp: float  # s, simulation time
    lo: float  # s: the bracket, lo < t_render <= hi
    hi: float
    error_bound: float  # s: |stamp - t_render| <= error_bound when the bracket is right
    method: str  # "grid" | "grid-partial" | "interval" | "elapsed"
    phase: int | None = None  # the render-clock phase used (grid), else None


@dataclass(frozen=True)
class Pending:
    """The stamp needs the next SensorFrame: ask again when one arrives, or at ``deadline`` (monotonic s)."""

    deadline: float


@dataclass
class StampCounters:
    grid: int = 0
    grid_partial: int = 0
    interval: int = 0
    overtaken: int = 0  # frames assigned to the SensorFrame that arrived before them
    waited: int = 0  # frames whose decision had to wait for the next SensorFrame (or the deadline)
    conflicts: int = 0  # stamp not after the previous one: nudged forward
    bracket_misses: int = 0  # the learned phase has no free render tick near the frame (stamped "interval")
    rebracketed: int = 0  # the grid put the frame in the other cycle than the bracket said
    sequenced: int = 0  # exact stamps that came from counting frames after the previous tick
    resyncs: int = 0  # the frame count contradicted the arrival times: the tick was looked for again
    no_clock: int = 0  # frames before any SensorFrame: not stamped
    elapsed: int = 0  # stamped by the elapsed-time rule
    clamped: int = 0  # elapsed rule: the frame came more than a cycle after its SensorFrame (clamped to it)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class CameraStamper:
    """Stamps camera frames with the simulation time they were rendered at (see the module docstring).

    Thread-safe: the UDP side calls :meth:`on_sensor_frame`, the camera side :meth:`stamp`, which returns a
    :class:`StampEstimate`, None (no SensorFrame yet) or :class:`Pending` (call again when the next
    SensorFrame is known, or at the deadline).
    """

    def __init__(self, period_ms: int = 40, render_fps: float = 60.0, decimation: int = 4,
                 max_wait: float = 0.02, window: int = 16, min_frames: int = 8, history: int = 512,
                 use_grid: bool = True, rule: str = "nearest", max_disagree: int = 5,
                 max_delay: float = 0.15, latency: float = 0.004, rate_window: float = 1.0,
                 wait_overdue: float = 0.3):
        if period_ms <= 0 or render_fps <= 0 or decimation < 1:
            raise ValueError(f"period_ms {period_ms}, render_fps {render_fps} must be > 0, decimation >= 1")
        if max_wait < 0:
            raise ValueError("max_wait must be >= 0")
        if rule not in RULES:
            raise ValueError(f"rule {rule!r}: one of {', '.join(RULES)}")
        if latency < 0 or rate_window <= 0 or wait_overdue < 0:
            raise ValueError(f"latency {latency} and wait_overdue {wait_overdue} must be >= 0, rate_window "
                             f"{rate_window} > 0")
        self.wait_overdue = float(wait_overdue)
        self.latency = float(latency)
        self.rate_window = float(rate_window)
        if max_disagree < 1 or max_delay <= 0:
            raise ValueError(f"max_disagree {max_disagree} must be >= 1, max_delay {max_delay} > 0")
        self.rule = rule
        self.max_disagree = int(max_disagree)
        self.max_delay = float(max_delay)
        self.period_ms = int(period_ms)
        self.fps = _fraction(render_fps)
        self.decimation = int(decimation)
        self.max_wait = float(max_wait)
        self.window = int(window)
        self.min_frames = int(min_frames)
        self.use_grid = bool(use_grid)
        self.counters = StampCounters()
        self._lock = threading.Lock()
        self._arrivals: deque[float] = deque(maxlen=history)
        self._tms: deque[int] = deque(maxlen=history)
        self._phases: deque[frozenset] = deque(maxlen=self.window)
        self._prev: float | None = None
        self._tick: int | None = None  # render tick of the last frame stamped on the grid
        self._disagree = 0  # consecutive frames whose counted tick was outside their bracket

    @property
    def grid_spacing(self) -> float:
        """Seconds of simulation time between published frames."""
        return float(self.decimation / self.fps)

    def reset(self) -> None:
        """Forget the stream (simulator restart): history, learned phase, monotonicity."""
        with self._lock:
            self._arrivals.clear()
            self._tms.clear()
            self._phases.clear()
            self._prev = None
            self._tick = None
            self._disagree = 0

    def resync_frames(self) -> None:
        """Forget what was learned from the frames (render phase, tick count, monotonicity) but keep the
        SensorFrames: the camera publisher restarted while the simulator's stream went on."""
        with self._lock:
            self._phases.clear()
            self._prev = None
            self._tick = None
            self._disagree = 0

    def on_sensor_frame(self, time_ms: int, arrival: float) -> None:
        """Record an accepted SensorFrame (``Tms``) and its arrival (monotonic seconds)."""
        with self._lock:
            if self._arrivals and arrival < self._arrivals[-1]:
                arrival = self._arrivals[-1]  # keep the history sorted (clock granularity)
            self._arrivals.append(arrival)
            self._tms.append(int(time_ms))

    @property
    def locked_phase(self) -> int | None:
        with self._lock:
            return self._locked()[0]

    def _locked(self) -> tuple[int | None, set]:
        """(the phase the recent frames agree on, or None; the phases allowed by all of them).

        With ``n`` frames in the window (at least ``min_frames``), a phase is locked when it is allowed by
        all of them but at most ``max(1, n // 8)`` (wrong brackets happen) and by at least two more frames
        than any other phase.
        """
        n = len(self._phases)
        if n == 0:
            return None, set(range(self.decimation))
        score = [0] * self.decimation
        for s in self._phases:
            for p in s:
                score[p] += 1
        strict = {p for p in range(self.decimation) if score[p] == n}
        if n >= self.min_frames:
            order = sorted(range(self.decimation), key=lambda p: -score[p])
            best = order[0]
            second = score[order[1]] if self.decimation > 1 else -10
            if score[best] >= n - max(1, n // 8) and score[best] - second >= 2:
                return best, strict
        return None, strict

    def _ticks(self, lo_ms: int, hi_ms: int) -> list[int]:
        """Render ticks k with lo < k/fps <= hi (milliseconds, exact)."""
        k_min = math.floor(Fraction(lo_ms, 1000) * self.fps) + 1
        k_max = math.floor(Fraction(hi_ms, 1000) * self.fps)
        return list(range(k_min, k_max + 1))

    def bracket(self, arrival: float, now: float) -> tuple[int, int, bool] | Pending | None:
        """(lo_ms, hi_ms, overtaken) for a frame that arrived at ``arrival``, known at wall time ``now``."""
        a, T = self._arrivals, self._tms
        i = bisect.bisect_right(a, arrival) - 1
        P = self.period_ms
        if i < 0:
            if a:  # a frame before the first SensorFrame we kept: it belongs to that one's cycle
                return T[0] - P, T[0], False
            return Pending(arrival + self.max_wait) if now < arrival + self.max_wait else None
        d_prev = arrival - a[i]
        if self.rule == "following":  # rendered after the last SensorFrame received: the cycle after it
            return T[i], T[i] + P, False
        if i + 1 < len(a):
            overtaken = d_prev <= a[i + 1] - arrival
            hi = T[i] if overtaken else T[i + 1]
        else:
            wait = min(d_prev, self.max_wait)
            if now < arrival + wait:
                return Pending(arrival + wait)
            overtaken = d_prev <= self.max_wait  # the next did not come within d_prev: the previous is nearer
            hi = T[i] if overtaken else T[i] + P
        return hi - P, hi, overtaken

    def stamp(self, arrival: float | None = None, now: float | None = None,
              skipped: int = 0) -> StampEstimate | Pending | None:
        """Estimate the render time of a camera frame that arrived at ``arrival`` (monotonic seconds).

        ``skipped``: frames the receiver got after the previous stamped frame and dropped unstamped (it keeps
        only the newest); they still used render ticks.
        """
        now = time.monotonic() if now is None else now
        arrival = now if arrival is None else arrival
        with self._lock:
            if self.rule == "elapsed":
                overdue = self._overdue(arrival, now)
                if overdue is not None:
                    return overdue
                est = self._from_elapsed(arrival)
                if est is None:
                    self.counters.no_clock += 1
                    return None
                if now > arrival:
                    self.counters.waited += 1
                return self._monotonic(est)
            br = self.bracket(arrival, now)
            c = self.counters
            if br is None:
                c.no_clock += 1
                return None
            if isinstance(br, Pending):
                return br
            lo, hi, overtaken = br
            c.overtaken += overtaken
            if now > arrival:
                c.waited += 1
            ticks = self._ticks(lo, hi)
            self._phases.append(frozenset(k % self.decimation for k in ticks))
            est = self._from_sequence(arrival, lo, hi, skipped) or self._from_brackets(lo, hi, overtaken, ticks)
            self._tick = round(est.stamp * self.fps) if est.method == "grid" else None
            if est.method == "grid":
                c.grid += 1
            elif est.method == "grid-partial":
                c.grid_partial += 1
            else:
                c.interval += 1
            return self._monotonic(est)

    def _monotonic(self, est: StampEstimate) -> StampEstimate:
        """Keep stamps strictly increasing: nudge one that is not 1 ms after the previous (counted)."""
        if self._prev is not None and est.stamp <= self._prev:
            self.counters.conflicts += 1
            nudged = self._prev + 1e-3
            est = StampEstimate(nudged, est.lo, est.hi, est.error_bound + (nudged - est.stamp), est.method,
                                est.phase)
            self._tick = None  # a nudged stamp is no tick to count from
        self._prev = est.stamp
        return est

    def rate(self, i: int | None = None) -> float:
        """Simulation seconds per wall second of the stream over ``rate_window`` wall seconds up to SensorFrame
        ``i`` of the history (default the newest); 1.0 while fewer than two SensorFrames span it."""
        a, T = self._arrivals, self._tms
        if i is None:
            i = len(a) - 1
        if i < 1:
            return 1.0
        j = bisect.bisect_left(a, a[i] - self.rate_window, 0, i)
        if j >= i or a[i] <= a[j]:
            j = max(0, i - 1)
        span = a[i] - a[j]
        return (T[i] - T[j]) / 1000 / span if span > 0 else 1.0

    def _overdue(self, arrival: float, now: float) -> Pending | None:
        """Elapsed rule: the next SensorFrame is overdue at the frame's arrival (more than 1.5 cycles of the
        stream's wall time after the last one known): it may have reached the bridge but not yet this stamper
        (a loaded bridge process). Wait for it up to ``wait_overdue`` wall seconds."""
        a = self._arrivals
        if not a or arrival <= a[-1] or now >= arrival + self.wait_overdue:
            return None
        if (arrival - a[-1]) * self.rate() * 1000 > 1.5 * self.period_ms:
            return Pending(arrival + self.wait_overdue)
        return None

    def _from_elapsed(self, arrival: float) -> StampEstimate | None:
        """The elapsed-time rule (module docstring): after the last SensorFrame received before the frame."""
        a, T, P = self._arrivals, self._tms, self.period_ms
        if not a:
            return None
        i = bisect.bisect_right(a, arrival) - 1
        self.counters.elapsed += 1
        if i < 0:  # before the oldest SensorFrame kept: it belongs to that one's cycle
            return StampEstimate(T[0] / 1000, (T[0] - P) / 1000, T[0] / 1000, P / 1000, "elapsed")
        gone = (arrival - a[i] - self.latency) * self.rate(i) * 1000  # ms of simulation since T_i
        if gone > P:
            self.counters.clamped += 1
        gone = min(max(gone, 0.0), float(P))
        return StampEstimate((T[i] + gone) / 1000, T[i] / 1000, (T[i] + P) / 1000, P / 1000, "elapsed")

    def _from_sequence(self, arrival: float, lo: int, hi: int, skipped: int) -> StampEstimate | None:
        """The tick after the previous frame's (plus the skipped frames), if the arrival times allow it."""
        if self._tick is None or not self.use_grid or self.grid_spacing * 1000 <= self.period_ms:
            return None
        d = self.decimation
        k = self._tick + d * (1 + max(0, int(skipped)))
        t_ms = Fraction(k) / self.fps * 1000
        i = bisect.bisect_right(self._arrivals, arrival) - 1
        upper = self._tms[i] + self.period_ms if i >= 0 else self._tms[0]  # rendered before this at the latest
        j = bisect.bisect_left(self._tms, math.ceil(t_ms))  # the SensorFrame sent just after tick k
        late = j < len(self._tms) and arrival - self._arrivals[j] > self.max_delay
        phase, _ = self._locked()
        self._disagree = 0 if lo < t_ms <= hi else self._disagree + 1
        if t_ms > min(upper, hi + self.period_ms) or late or (phase is not None and phase != k % d) \
                or self._disagree >= self.max_disagree:
            self.counters.resyncs += 1
            self._disagree = 0
            return None
        self.counters.sequenced += 1
        if not lo < t_ms <= hi:
            self.counters.rebracketed += 1
        return StampEstimate(float(k / self.fps), lo / 1000, hi / 1000, 0.0, "grid", k % d)

    def _from_brackets(self, lo: int, hi: int, overtaken: bool, ticks: list[int]) -> StampEstimate:
        """The stamp from the bracket and the render phase the recent brackets agree on (if any)."""
        c, d = self.counters, self.decimation
        phase, strict = self._locked() if self.use_grid else (None, set())
        if len(self._phases) < self.min_frames:
            strict = set()  # too few frames to trust the render grid yet
        lo_s, hi_s = lo / 1000, hi / 1000
        cand: list[int] = []
        if phase is not None and self.grid_spacing * 1000 <= self.period_ms:
            cand = [k for k in ticks if k % d == phase]  # several published ticks per cycle
            if not cand:
                c.bracket_misses += 1
        elif phase is not None:
            t_prev = hi if overtaken else lo  # the SensorFrame before the frame; its cycle and the next
            prev = self._prev if self._prev is not None else float("-inf")
            wide = [k for k in self._ticks(t_prev - self.period_ms, t_prev + self.period_ms)
                    if k % d == phase and float(k / self.fps) > prev + 1e-9]
            cand = wide if len(wide) <= 1 else [k for k in wide if lo < float(k / self.fps) * 1000 <= hi + 1e-9]
            if not cand:
                c.bracket_misses += 1  # the learned phase has no free tick near this frame
            elif len(cand) == 1:
                k_ms = float(cand[0] / self.fps) * 1000
                if not (lo < k_ms <= hi + 1e-9):
                    c.rebracketed += 1
                    lo_s, hi_s = ((hi, hi + self.period_ms) if k_ms > hi else (lo - self.period_ms, lo))
                    lo_s, hi_s = lo_s / 1000, hi_s / 1000
        elif strict:
            cand = [k for k in ticks if k % d in strict]
        if len(cand) == 1 and phase is not None:
            return StampEstimate(float(cand[0] / self.fps), lo_s, hi_s, 0.0, "grid", phase)
        if cand:  # several candidate ticks (phase not settled, or several published ticks per cycle)
            t0, t1 = float(cand[0] / self.fps), float(cand[-1] / self.fps)
            return StampEstimate((t0 + t1) / 2, lo_s, hi_s, (t1 - t0) / 2, "grid-partial", phase)
        return StampEstimate((lo + hi) / 2000, lo / 1000, hi / 1000, self.period_ms / 2000, "interval")


@dataclass
class SimClock:
    """The simulation time known from the stream, and the real-time factor over a sliding window."""

    window: float = 2.0  # s (wall)
    _hist: deque = field(default_factory=lambda: deque(maxlen=4096))

    def on_sensor_frame(self, time_ms: int, arrival: float) -> None:
        self._hist.append((arrival, int(time_ms)))

    def reset(self) -> None:
        self._hist.clear()

    @property
    def time_ms(self) -> int | None:
        return self._hist[-1][1] if self._hist else None

    def real_time_factor(self, now: float | None = None) -> float:
        """Simulation seconds per wall second over the window (0 when unknown)."""
        h = self._hist
        if len(h) < 2:
            return 0.0
        now = time.monotonic() if now is None else now
        recent = [(a, t) for a, t in h if a >= now - self.window]
        if len(recent) < 2:
            return 0.0
        (a0, t0), (a1, t1) = recent[0], recent[-1]
        span = max(now - a0, a1 - a0) if now - a1 < 0.5 else now - a0
        return (t1 - t0) / 1000 / span if span > 0 else 0.0
