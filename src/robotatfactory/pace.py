"""Pacing the whole stack by simulation time (issue 23): the bookkeeping, with no middleware.

In a paced run (``raf sim --paced``) the simulator waits for the reply to every frame, and the bridge
replies to frame k only once the agent has decided on it. Every node of the loop works cycle by cycle and,
when it has finished cycle k (stamp t_k), publishes a *pace* message: its name, the stamp, and how many
messages it has published so far on each of its outputs (``odom``, ``scan``, ``image``, ``pose``, ...). A node
downstream starts cycle k only when each node it depends on has paced t_k and it has received at least that
many messages on each input it takes from that node. Topics of one publisher are separate connections (their
messages may arrive in any order), so a stamp alone could not say that nothing is still on its way; the counts
can. The result does not depend on how the messages were scheduled: a paced run is reproducible.

The loop, per cycle k: raf sim -> bridge (odom, scan, contact, ...; pace) and camera (images; pace) ->
localization (pose; pace) -> agent (cmd_vel, electromagnet; pace) -> the bridge's reply to frame k.

:class:`PaceBook` is what one node knows: the counts it has received and the paces of the nodes it needs.
:class:`PaceCounts` is what it has published. ``ros/pace.py`` carries both over the middleware.
"""
from __future__ import annotations

import math
import threading
import time
from collections import Counter
from dataclasses import dataclass, field

from .settings import setting

#: stamps of one cycle agree to this (s): they are all the SensorFrame's Tms, in ms
STAMP_TOLERANCE = 5e-4


@dataclass(frozen=True)
class PaceSettings:
    """``pace.*``: the same section in each paced node's settings (bridge, camera, localization, agent)."""

    enabled: bool = setting(False, "paced by simulation time (raf sim --paced --pace-hold 2): work cycle by "
                                   "cycle, wait for the inputs each upstream node paced, then pace the cycle "
                                   "(docs/pacing.md)")
    timeout: float = setting(5.0, "wall s a cycle waits for its inputs before it runs without them (warned and "
                                  "counted: a safety net, never reached in a sound run)", lo=0.0, lo_open=True)


@dataclass
class Pace:
    """One pace message: ``name`` finished the cycle stamped ``t`` (s) having published ``counts``."""

    name: str
    t: float
    counts: dict[str, int] = field(default_factory=dict)


class PaceCounts:
    """The messages a node has published, per output key (thread-safe)."""

    def __init__(self, name: str):
        self.name = name
        self._counts: Counter = Counter()
        self._lock = threading.Lock()

    def sent(self, key: str, n: int = 1) -> None:
        with self._lock:
            self._counts[key] += n

    def pace(self, t: float) -> Pace:
        with self._lock:
            return Pace(self.name, float(t), dict(self._counts))


class PaceBook:
    """What one paced node has received and what the nodes it depends on have paced.

    ``needs`` maps each upstream node's name to the keys this node takes from it (e.g. ``{"bridge": ("odom",
    "scan"), "camera": ("image",)}``); the first upstream node's paces define the cycles. Thread-safe: input
    callbacks call :meth:`got`, the pace subscription :meth:`paced`; :meth:`next_ready` says which cycle may
    run now, :meth:`wait` blocks for one (with a wall-clock limit, a safety net: a paced run never hangs)."""

    def __init__(self, needs: dict[str, tuple[str, ...]], behind: dict[str, tuple[str, ...]] | None = None):
        if not needs:
            raise ValueError("a paced node needs at least one upstream node")
        self.needs = {k: tuple(v) for k, v in needs.items()}
        #: upstream nodes downstream of this one in the loop (the agent, for the localization): cycle k needs
        #: their pace of the cycle before (k - 1), and the messages it counts
        self.behind = {k: tuple(v) for k, v in (behind or {}).items()}
        self.clock = next(iter(self.needs))
        self.received: Counter = Counter()
        self._paces: dict[str, list[Pace]] = {k: [] for k in (*self.needs, *self.behind)}
        self.done_t = -math.inf  # the latest cycle this node has run
        self.timeouts = 0
        self._cv = threading.Condition()

    # ---- inputs ----------------------------------------------------------------------------------------
    def got(self, key: str, n: int = 1) -> None:
        """``n`` messages on input ``key`` received (call after the message is stored where the cycle reads it)."""
        with self._cv:
            self.received[key] += n
            self._cv.notify_all()

    def paced(self, p: Pace) -> None:
        """A pace message (those of nodes this one does not need are ignored)."""
        if p.name not in self._paces or not math.isfinite(p.t):
            return
        with self._cv:
            self._paces[p.name].append(p)
            self._cv.notify_all()

    # ---- cycles ----------------------------------------------------------------------------------------
    def _of(self, name: str, t: float) -> Pace | None:
        return next((p for p in self._paces[name] if abs(p.t - t) <= STAMP_TOLERANCE), None)

    def _wants(self, t: float):
        """(upstream name, stamp of the pace cycle ``t`` needs from it, keys) of every requirement of ``t``."""
        out = [(name, t, keys) for name, keys in self.needs.items()]
        if self.done_t > -math.inf:  # (the first cycle has none before it)
            out += [(name, self.done_t, keys) for name, keys in self.behind.items()]
        return out

    def _ready(self, t: float) -> bool:
        for name, at, keys in self._wants(t):
            p = self._of(name, at)
            if p is None or any(self.received[k] < p.counts.get(k, 0) for k in keys):
                return False
        return True

    def _next_t(self) -> float | None:
        later = [p.t for p in self._paces[self.clock] if p.t > self.done_t + STAMP_TOLERANCE]
        return min(later) if later else None

    def pending(self) -> float | None:
        """The next cycle's stamp (ready or not), or None while no upstream pace has announced one."""
        with self._cv:
            return self._next_t()

    def next_ready(self) -> float | None:
        """The next cycle's stamp if everything it needs is in, else None."""
        with self._cv:
            t = self._next_t()
            return t if t is not None and self._ready(t) else None

    def wait(self, t: float, timeout: float) -> bool:
        """Block until cycle ``t`` is ready (True) or ``timeout`` wall seconds passed (False, counted)."""
        end = time.monotonic() + timeout
        with self._cv:
            while not self._ready(t):
                left = end - time.monotonic()
                if left <= 0:
                    self.timeouts += 1
                    return False
                self._cv.wait(min(left, 0.1))
            return True

    def done(self, t: float) -> None:
        """Cycle ``t`` has run: forget the paces up to it."""
        with self._cv:
            self.done_t = max(self.done_t, t)
            for name in self._paces:  # (a node behind keeps the pace of t: the next cycle needs it)
                keep = t - STAMP_TOLERANCE if name in self.behind else t + STAMP_TOLERANCE
                self._paces[name] = [p for p in self._paces[name] if p.t > keep]
            self._cv.notify_all()

    def backlog(self) -> int:
        """How many paces are held (those of cycles not yet done): stays small in a sound run."""
        with self._cv:
            return sum(len(v) for v in self._paces.values())

    def wait_done(self, t: float, timeout: float) -> bool:
        """Block until cycle ``t`` has run (True) or ``timeout`` wall seconds passed (False): for a thread that
        found another one running it."""
        end = time.monotonic() + timeout
        with self._cv:
            while self.done_t < t - STAMP_TOLERANCE:
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cv.wait(min(left, 0.1))
            return True

    def required(self, t: float) -> dict[str, int]:
        """The messages cycle ``t`` counts on each input (those of the paces it waits for; a key whose pace has
        not come is left out). Call before :meth:`done` (a node behind is asked for its previous cycle)."""
        with self._cv:
            out: dict[str, int] = {}
            for name, at, keys in self._wants(t):
                p = self._of(name, at)
                if p is not None:
                    out.update({k: p.counts.get(k, 0) for k in keys})
            return out

    def missing(self, t: float) -> str:
        """What cycle ``t`` still waits for, in words (for a timeout's warning)."""
        with self._cv:
            out = []
            for name, at, keys in self._wants(t):
                p = self._of(name, at)
                if p is None:
                    out.append(f"{name}'s pace of {at:.3f} s")
                    continue
                out += [f"{k} {self.received[k]}/{p.counts.get(k, 0)}" for k in keys
                        if self.received[k] < p.counts.get(k, 0)]
            return ", ".join(out) or "nothing"

    def give_up(self, t: float) -> None:
        """After a timeout: take what was received as complete, so the counts match again from here."""
        with self._cv:
            for name, at, keys in self._wants(t):
                p = self._of(name, at)
                if p is not None:
                    for k in keys:
                        self.received[k] = max(self.received[k], p.counts.get(k, 0))
