"""LIDAR sweeps from the range arrays of SimTwo's ``ranger2d``: which sweep an array holds and when its rays
were measured (the ``LaserScan`` stamp).

Plain Python, no ROS. Times: the stream's simulation time ``Tms`` (integer milliseconds at the end of each
control cycle, period ``D`` = 40 ms) and seconds; ``P`` is the ranger's sweep period (0.2 s).

**What SimTwo does** (source references to ``P33a/SimTwo``; docs/bridge.md has the details). Every physics
step (1 ms) ``TSensor.PreProcess`` (``ODERobots.pas`` 1593-1624, called at ``Viewer.pas`` 5414-5417) enables
the few rays whose turn it is, ``first_active_ray = round(N * TimeFromLastMeasure / P)``, and ODE measures
them in that step's ``dSpaceCollide`` (``Viewer.pas`` 4370-4373, ``nearCallback`` 346-410): the rays are
*measured* in turn over the period. But what a script reads (``GetSensorValues``,
``ODERobotsPublished.pas`` 1107-1117) is ``Measures[]``, which ``UpdateMeasures`` (``ODERobots.pas``
1842-1846) copies from all rays at once when ``TimeFromLastMeasure`` exceeds ``P`` (``Viewer.pas``
5446-5452): the values are *delivered* a whole sweep at once, once per period, and are 0 before the first
delivery (the ``TSensorMeasure`` objects start zeroed: ``ODERobots.pas`` 1553-1560, 2239-2242). Ray ``i`` of
the sweep delivered at ``t_u`` was measured at ``t_u - P + i * P / N`` (within 1.5 ms: ``rolling`` ray
timing, the default). A stand-in that measures every ray at the delivery
instant is ``ray_timing="instant"`` (``t0 = t_u``, ``time_increment = 0``).

**Whole-sweep mode** (:class:`WholeSweepAssembler`, the default):

* An array whose every value lies in ``[0, zero_below)`` is SimTwo's array before its first sweep (0, plus
  the noise control.pas adds): nothing is published.
* A sweep is delivered between two control cycles; the bridge only sees *that* the array changed, in the
  frame after the delivery: the delivery instant ``t_u`` lies in ``(Tms_prev, Tms]`` (the bracket), where
  ``Tms_prev`` is the previous frame received (a lost frame widens the bracket).
* **Phase.** Deliveries repeat every ``P`` exactly (SimTwo's sensor clock and script clock both count the
  same 1 ms physics steps; an emulation of ``Viewer.pas`` 5228-5231 and 5446-5452 in float64 shows 200 and 40
  steps, without drift, over 2000 s), so ``t_u = phase + k * P``. Each change gives the phases its bracket
  allows; their intersection is the phase. It is locked after the first sweep that follows the all-zero
  array (a change there is certainly a delivery) or after ``lock_after`` changes that agree. With
  ``P`` a multiple of ``D`` every bracket gives the same 40 ms arc (``|error| <= D/2``); otherwise the
  arc narrows as brackets accumulate.
* **Locked**: every sweep ``k`` is published once, from the first frame that certainly holds it
  (``Tms >=`` the latest possible ``t_u`` of sweep ``k``, and before the earliest possible next delivery),
  *whether or not its array changed*: a static scene in a noise-free run delivers identical sweeps, which
  are sweeps all the same (``repeated`` counts them). A lost frame costs nothing (the sweep is still in the
  next frame); a sweep whose every frame was lost is counted (``lost``). A change off the locked phase is no
  delivery (``off_phase``: e.g. noise redrawn by the script between deliveries); ``relock_after``
  consecutive off-phase changes that agree with each other move the phase (``relocks``).
* **Not locked** (a bridge that joined a running simulation and has seen no change yet, or after a
  contradiction): a change is published with the bracket's middle when the bracket allows ``|error| <=
  max_error`` (default ``D``) and when it comes more than ``P`` after the previous published one (two
  deliveries are ``P`` apart; a closer change is no delivery). Identical arrays give nothing: before the
  first change the delivery instant of the array is unknown (within ``P``), so the first array seen
  mid-run is not published (``unstamped``).
* **Where in the bracket.** SimTwo's sensor clock and its script clock start together (``SecondsCount := 0``
  at ``Viewer.pas`` 4245; ``TimeFromLastMeasure`` 0 when the sensor is created with the scene) and both
  count 1 ms steps with ``>`` tests on float64 sums: the script runs at the start of step 40 m and sees the
  state after 40 m - 1 steps; the sweep is delivered at the end of step 200 j, i.e. 1 ms after a script
  call (H2's reading of the same lines agrees; the stand-in reproduces it). So the estimate is placed
  ``delivery_lag`` = 1 ms after the frame before the bracket (``delivery_lag=None``: the bracket's middle).
  The stamp then has the error of the model (<= 1.5 ms) when SimTwo aligns as read, and at worst the arc's
  width (39 ms) if it does not (``error_bound`` reports that worst case); with ``delivery_lag=None``, or
  when an arc is wider than a cycle (frames lost) so that only its middle stays within ``max_error``, at
  worst half the arc (19.5 ms for one cycle). Either way within one control cycle, as required.

**Per-ray mode** (:class:`PerRayAssembler`, ``update="per_ray"``): the idealisation in which the array a
frame carries shows each ray as soon as it is measured (ray ``i`` of sweep ``s`` at the first physics step
after ``(s + i / N) * P``). It reassembles time-ordered sweeps from the mixed arrays; rays only carried by
lost frames are NaN. It matches the stand-in's ``--lidar-update per_ray``; used on SimTwo it stamps every
scan one sweep (0.2 s) late.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

UPDATE_MODES = ("sweep", "per_ray")
RAY_TIMINGS = ("rolling", "instant")


@dataclass(frozen=True)
class Sweep:
    """One complete LIDAR sweep: ray ``i`` measured at ``t0 + i * time_increment`` (simulation seconds)."""

    index: int  # sweep number since Tms 0 (per-ray, locked whole-sweep) or since the start (not locked)
    t0: float  # s, time of ray 0 (the LaserScan's header.stamp)
    time_increment: float  # s between consecutive rays
    ranges: np.ndarray  # metres, -1 = no return, NaN = not received (per-ray mode, datagrams lost)
    missing: int = 0  # rays not received
    error_bound: float = 0.0  # s: |t0 - true time of ray 0| <= error_bound (plus one physics step)
    method: str = "schedule"  # "schedule" (per-ray) | "phase" (locked) | "bracket" (not locked)


@dataclass
class ScanCounters:
    """What an assembler did (diagnostics)."""

    frames: int = 0  # arrays offered
    pre_sweep: int = 0  # arrays before the first sweep (all values below zero_below)
    changes: int = 0  # arrays that differed from the previous one
    sweeps: int = 0  # sweeps returned (published)
    repeated: int = 0  # sweeps published on the locked phase with the same values as the previous sweep
    off_phase: int = 0  # changes that are no delivery (off the locked phase, or too soon after the last)
    unstamped: int = 0  # sweeps seen but not published: delivery instant unknown within max_error
    lost: int = 0  # sweeps never seen (every frame that held them was lost)
    missing_rays: int = 0  # per-ray mode: rays not received
    locks: int = 0  # times the delivery phase was locked
    relocks: int = 0  # times a locked phase was replaced by consistent off-phase changes
    restarts: int = 0  # Tms went back without reset() (a restart the caller did not report)

    def as_dict(self, prefix: str = "") -> dict:
        return {prefix + k: v for k, v in asdict(self).items()}


def _check(rays: int, period: float) -> None:
    if rays < 1 or period <= 0:
        raise ValueError(f"rays {rays} and period {period} must be positive")


class WholeSweepAssembler:
    """Sweeps from a ranger that delivers all rays at once every ``period`` (SimTwo). See the module doc."""

    def __init__(self, rays: int, period: float, control_period: float, ray_timing: str = "rolling",
                 zero_below: float = 0.02, max_error: float | None = None, lock_after: int = 2,
                 relock_after: int = 3, delivery_lag: float | None = 0.001):
        _check(rays, period)
        if ray_timing not in RAY_TIMINGS:
            raise ValueError(f"ray_timing {ray_timing!r}: one of {RAY_TIMINGS}")
        p_ms, d_ms = period * 1000, control_period * 1000
        if abs(p_ms - round(p_ms)) > 1e-6 or abs(d_ms - round(d_ms)) > 1e-6 or round(d_ms) < 1:
            raise ValueError(f"period {period} and control_period {control_period} must be whole milliseconds")
        self.n = int(rays)
        self.period_ms = int(round(p_ms))
        self.control_ms = int(round(d_ms))
        self.ray_timing = ray_timing
        self.zero_below = float(zero_below)
        self.max_error_ms = self.control_ms if max_error is None else float(max_error) * 1000
        self.lock_after = max(1, int(lock_after))
        self.relock_after = max(1, int(relock_after))
        if delivery_lag is not None and not 0 < delivery_lag <= control_period:
            raise ValueError(f"delivery_lag {delivery_lag} must be in (0, control_period] or None")
        # ms from the frame before a delivery to the delivery (SimTwo: 1), None = unknown (bracket middle)
        self.lag_ms = None if delivery_lag is None else float(delivery_lag) * 1000
        self.counters = ScanCounters()
        self.reset()

    # ---- state -------------------------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the stream (simulator restart): arrays, phase, published sweeps (counters are kept)."""
        self._prev: np.ndarray | None = None  # previous array
        self._prev_t: int | None = None  # its Tms
        self._prev_zero = False  # the previous array was the all-zero one
        self._cand: np.ndarray | None = None  # phases allowed by the changes so far (not locked)
        self._cand_n = 0
        self.phase: np.ndarray | None = None  # locked: bool[P_ms], the phases (ms) the deliveries may have
        self._contra: np.ndarray | None = None  # off-phase changes that agree with each other
        self._contra_n = 0
        self._next_k: int | None = None  # lattice index of the next sweep to publish (locked)
        self._last_lo: int | None = None  # bracket start of the last published sweep (ms)
        self._last_pub: np.ndarray | None = None
        self._count = 0  # sweeps published since the start (index when not locked)

    @property
    def locked(self) -> bool:
        return self.phase is not None

    @property
    def sweeps_done(self) -> int:
        return self.counters.sweeps

    @property
    def missing_total(self) -> int:
        return self.counters.missing_rays

    # ---- phases ------------------------------------------------------------------------------------------
    def _mask(self, lo: int, hi: int) -> np.ndarray:
        """Phases (ms, mod P) of the instants t with lo < t <= hi."""
        p = self.period_ms
        m = np.zeros(p, dtype=bool)
        if hi - lo >= p:
            m[:] = True
        else:
            m[np.arange(lo + 1, hi + 1) % p] = True
        return m

    def _arc(self, mask: np.ndarray) -> tuple[int, int]:
        """(start, width) in ms of the shortest arc covering the allowed phases: start <= phase <= start+width."""
        p = self.period_ms
        idx = np.flatnonzero(mask)
        if len(idx) == p:
            return 0, p - 1
        # the arc starts just after the longest run of disallowed phases
        gaps = np.diff(np.concatenate([idx, [idx[0] + p]]))
        j = int(np.argmax(gaps))
        start = int(idx[(j + 1) % len(idx)])
        end = int(idx[j])
        return start, (end - start) % p

    def _observe(self, lo: int, hi: int, trusted: bool) -> bool:
        """A change seen in the frame at ``hi`` (previous frame at ``lo``). Returns False when it is off the
        locked phase (no delivery)."""
        c = self.counters
        m = self._mask(lo, hi)
        if m.all():
            return self.phase is None  # a bracket as long as the period says nothing about the phase
        if self.phase is None:
            both = m if self._cand is None else (self._cand & m)
            if not both.any():  # disagrees with the earlier changes: start again from this one
                both, self._cand_n = m, 0
            self._cand, self._cand_n = both, self._cand_n + 1
            if trusted or self._cand_n >= self.lock_after:
                self.phase, self._cand, self._cand_n = both.copy(), None, 0
                c.locks += 1
            return True
        both = self.phase & m
        if both.any():
            self.phase = both
            self._contra, self._contra_n = None, 0
            return True
        agree = None if self._contra is None else (self._contra & m)
        if agree is None or not agree.any():
            self._contra, self._contra_n = m, 1
        else:
            self._contra, self._contra_n = agree, self._contra_n + 1
        if self._contra_n >= self.relock_after:
            self.phase, self._contra, self._contra_n = self._contra, None, 0
            self._next_k = None
            c.relocks += 1
            return True
        return False

    # ---- sweeps ------------------------------------------------------------------------------------------
    def _sweep(self, index: int, t_u_ms: float, bound_ms: float, ranges: np.ndarray, method: str) -> Sweep | None:
        c = self.counters
        p = self.period_ms / 1000
        if self.ray_timing == "rolling":
            t0, inc = (t_u_ms / 1000) - p, p / self.n
        else:
            t0, inc = t_u_ms / 1000, 0.0
        if t0 < 0:  # measured (partly) before Tms 0 (the script started after the simulation): no valid stamp
            c.unstamped += 1
            return None
        if self._last_pub is not None and np.array_equal(ranges, self._last_pub, equal_nan=True):
            c.repeated += 1
        self._last_pub = ranges.copy()
        c.sweeps += 1
        self._count += 1
        return Sweep(index, t0, inc, ranges.copy(), 0, bound_ms / 1000, method)

    def _from_phase(self, t: int, ranges: np.ndarray) -> Sweep | None:
        """The newest sweep certainly in the frame at ``t`` on the locked phase, unless already published."""
        p = self.period_ms
        start, width = self._arc(self.phase)
        k = (t - start - width) // p  # newest sweep whose latest possible delivery is <= t
        if t >= start + (k + 1) * p:
            return None  # the next delivery may already be in this array: decide on the next frame
        if self._next_k is not None and k < self._next_k:
            return None  # published already
        if self._next_k is not None and k > self._next_k:
            self.counters.lost += k - self._next_k
        self._next_k = k + 1
        self._last_lo = start + k * p - 1
        pos, bound = self._place(width)
        return self._sweep(int(k), start + k * p + pos, bound, ranges, "phase")

    def _from_change(self, lo: int, t: int, ranges: np.ndarray) -> Sweep | None:
        """A change seen at ``t`` (previous frame at ``lo``) without a locked phase."""
        c = self.counters
        if self._last_lo is not None and t <= self._last_lo + self.period_ms:
            c.off_phase += 1  # less than a period after the last delivery: not a delivery
            return None
        pos, bound = self._place(t - lo - 1)
        if bound > self.max_error_ms:
            c.unstamped += 1
            return None
        self._last_lo = lo
        return self._sweep(self._count, lo + 1 + pos, bound, ranges, "bracket")

    def _place(self, width: float) -> tuple[float, float]:
        """Where in an arc of allowed delivery instants ``[start, start + width]`` (ms) the estimate goes, and
        its worst-case error given only the arc: the middle, or ``delivery_lag`` after the frame before it
        (the arc's start is 1 ms after that frame), kept inside the arc."""
        if self.lag_ms is not None:
            pos = min(max(self.lag_ms - 1, 0.0), width)
            if max(pos, width - pos) <= self.max_error_ms:
                return pos, max(pos, width - pos)
        return width / 2, width / 2  # no lag known, or a wide arc (frames lost) where only the middle is safe

    def add(self, time_ms: int, ranges) -> list[Sweep]:
        """Feed the array of the frame at ``time_ms``; returns the sweeps to publish (0 or 1)."""
        c = self.counters
        r = np.array(ranges, dtype=float)
        if r.shape != (self.n,):
            raise ValueError(f"{r.size} rays, expected {self.n}")
        t = int(time_ms)
        c.frames += 1
        if self._prev_t is not None and t <= self._prev_t:
            c.restarts += 1  # time went back: the simulator restarted
            self.reset()
        if bool(np.all((r >= 0) & (r < self.zero_below))):
            c.pre_sweep += 1  # SimTwo's array before its first sweep (0, plus the script's noise)
            self._prev, self._prev_t, self._prev_zero = r, t, True
            return []
        lo, prev, after_zero = self._prev_t, self._prev, self._prev_zero
        self._prev, self._prev_t, self._prev_zero = r, t, False
        out: Sweep | None = None
        if prev is None:  # joined a running simulation: when this sweep was delivered is unknown
            c.unstamped += 1
            return []
        changed = not np.array_equal(r, prev, equal_nan=True)
        on_phase = True
        if changed:
            c.changes += 1
            on_phase = self._observe(lo, t, trusted=after_zero)
        if self.phase is not None:
            if changed and not on_phase:
                c.off_phase += 1
            out = self._from_phase(t, r)
        elif changed:
            out = self._from_change(lo, t, r)
        return [out] if out is not None else []


class PerRayAssembler:
    """Rebuilds time-ordered LIDAR sweeps from arrays that show each ray as soon as it is measured.

    The ranger refreshes its N rays in turn over one ``period``: ray ``i`` of sweep ``s`` is measured at the
    end of the first physics step after ``(s + i/N) * period`` (simulation time from 0). The array a
    SensorFrame carries at the end of a cycle therefore mixes the newest rays of the current sweep with the
    older rest of the previous one, which a ``sensor_msgs/LaserScan`` (one start time, a fixed increment)
    cannot describe. From the schedule the assembler knows which sweep each ray of each array belongs to,
    collects every sweep, and returns it once its last ray has been measured. Rays whose only copies were
    in lost datagrams are NaN and counted. (The stand-in's ``--lidar-update per_ray``; not SimTwo.)
    """

    def __init__(self, rays: int, period: float, physics_step: float):
        if rays < 1 or period <= 0 or physics_step <= 0:
            raise ValueError(f"rays {rays}, period {period} and physics_step {physics_step} must be positive")
        self.n = int(rays)
        self._dt_ns = int(round(physics_step * 1e9))
        self._period_ns = int(round(period * 1e9))
        self._idx = np.arange(self.n)
        self.counters = ScanCounters()
        self.reset()

    @property
    def sweeps_done(self) -> int:
        return self.counters.sweeps

    @property
    def missing_total(self) -> int:
        return self.counters.missing_rays

    def reset(self) -> None:
        self._cur: int | None = None
        self._buf = np.full(self.n, np.nan)
        self._have = np.zeros(self.n, dtype=bool)

    def count(self, time_ms: int) -> int:
        """Rays measured since t = 0 by the end of the physics step ending at ``time_ms``."""
        steps = (int(time_ms) * 1_000_000) // self._dt_ns
        return (steps * self.n * self._dt_ns) // self._period_ns

    def ray_time(self, counter: int) -> float:
        """Simulation time (s) at which the ray with global counter ``counter`` is measured."""
        step = -(-(counter + 1) * self._period_ns // (self.n * self._dt_ns))  # first step whose count > counter
        return step * self._dt_ns / 1e9

    def add(self, time_ms: int, ranges) -> list[Sweep]:
        """Feed the array of the frame at ``time_ms``; returns the sweeps completed by it (usually 0 or 1)."""
        ranges = np.asarray(ranges, dtype=float)
        if len(ranges) != self.n:
            raise ValueError(f"{len(ranges)} rays, expected {self.n}")
        self.counters.frames += 1
        c = self.count(time_ms)
        if c == 0:
            return []
        # sweep each ray's newest measurement belongs to: counter = largest s*N + i below c
        sweep_of = (c - 1 - self._idx) // self.n  # -1 for rays not yet measured at all
        newest = (c - 1) // self.n
        if self._cur is None:
            self._cur = newest  # join at the sweep in progress (its first rays are in this array)
        elif self._cur < newest - 1:
            self.counters.lost += newest - 1 - self._cur
            self._cur = newest - 1  # a long gap: sweeps before it are gone
            self._buf[:] = np.nan
            self._have[:] = False
        out = []
        while True:
            sel = sweep_of == self._cur
            self._buf[sel] = ranges[sel]
            self._have |= sel
            if c >= (self._cur + 1) * self.n:  # its last ray has been measured
                missing = int(self.n - self._have.sum())
                t0 = self.ray_time(self._cur * self.n)
                t_last = self.ray_time(self._cur * self.n + self.n - 1)
                inc = (t_last - t0) / (self.n - 1) if self.n > 1 else 0.0
                out.append(Sweep(self._cur, t0, inc, self._buf.copy(), missing, self._dt_ns / 1e9, "schedule"))
                self.counters.sweeps += 1
                self.counters.missing_rays += missing
                self._cur += 1
                self._buf[:] = np.nan
                self._have[:] = False
                continue
            break
        return out


def make_assembler(update: str, rays: int, period: float, control_period: float, physics_step: float,
                   ray_timing: str = "rolling", zero_below: float = 0.02, max_error: float | None = None,
                   delivery_lag: float | None = 0.001) -> WholeSweepAssembler | PerRayAssembler:
    """The assembler for a ranger that updates its values a whole ``"sweep"`` at once (SimTwo, the default)
    or ``"per_ray"`` (the stand-in's idealisation)."""
    if update == "sweep":
        return WholeSweepAssembler(rays, period, control_period, ray_timing, zero_below, max_error,
                                   delivery_lag=delivery_lag)
    if update == "per_ray":
        return PerRayAssembler(rays, period, physics_step)
    raise ValueError(f"update {update!r}: one of {UPDATE_MODES}")
