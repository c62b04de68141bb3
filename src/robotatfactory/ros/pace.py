"""Pace messages over the middleware (see :mod:`robotatfactory.pace`): topic ``pace`` (relative: each robot's
nodes pace among themselves), ``diagnostic_msgs/DiagnosticArray`` with the cycle's stamp in the header and one
status per message: ``name`` the node's role, one ``KeyValue`` per output (key, messages published so far)."""
from __future__ import annotations

import threading
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ..pace import Pace, PaceBook, PaceCounts
from . import messages as rm
from .mw import QoS

TOPIC = "pace"
DEPTH = 100
#: wall s a paced node waits for a cycle's inputs before it runs the cycle anyway (warned and counted)
TIMEOUT = 5.0


def to_msg(p: Pace) -> DiagnosticArray:
    m = DiagnosticArray()
    m.header.stamp = rm.stamp_s(p.t)
    st = DiagnosticStatus()
    st.level = DiagnosticStatus.OK
    st.name = p.name
    st.message = "pace"
    st.values = [KeyValue(key=k, value=str(int(v))) for k, v in sorted(p.counts.items())]
    m.status = [st]
    return m


def from_msg(m: DiagnosticArray) -> list[Pace]:
    t = rm.stamp_to_s(m.header.stamp)
    out = []
    for st in m.status:
        try:
            out.append(Pace(st.name, t, {kv.key: int(kv.value) for kv in st.values}))
        except ValueError:  # not a count: not a pace message
            continue
    return out


class Pacer:
    """A node's side of pacing: counts what it publishes (:meth:`sent`) and receives (:meth:`got`), publishes
    its pace (:meth:`done`) and runs ``on_cycle(t)`` for each cycle once its inputs are in (in order, one at a
    time, from whichever callback completed them). ``needs``, ``behind``: see :class:`~robotatfactory.pace.PaceBook`;
    None for a node that only publishes its pace (the bridge waits with :meth:`wait` instead)."""

    def __init__(self, node, name: str, needs: dict[str, tuple[str, ...]] | None,
                 on_cycle: Callable[[float], None] | None = None, timeout: float = TIMEOUT,
                 behind: dict[str, tuple[str, ...]] | None = None):
        self.node, self.name, self.timeout = node, name, timeout
        self.out = PaceCounts(name)
        self.book = PaceBook(needs, behind) if needs else None
        self.on_cycle = on_cycle
        self._run_lock = threading.Lock()
        self.pub = node.publisher(TOPIC, DiagnosticArray, QoS.RELIABLE, DEPTH)
        self.sub = node.subscribe(TOPIC, DiagnosticArray, self._on_pace, QoS.RELIABLE, DEPTH) if needs else None
        self._running = True
        if on_cycle is not None:  # the safety net: a cycle whose inputs never all come runs after the timeout
            threading.Thread(target=self._watch, name=f"raf-pace-{name}", daemon=True).start()

    def close(self) -> None:
        self._running = False

    def sent(self, key: str, n: int = 1) -> None:
        self.out.sent(key, n)

    def done(self, t: float) -> None:
        self.pub.publish(to_msg(self.out.pace(t)))

    def got(self, key: str) -> None:
        self.book.got(key)
        self.advance()

    def _on_pace(self, m: DiagnosticArray) -> None:
        for p in from_msg(m):
            self.book.paced(p)
        self.advance()

    def advance(self) -> None:
        """Run every cycle that is ready, in order (callbacks of other threads that find the lock taken leave
        it to the one running: it loops until nothing is ready)."""
        if self.on_cycle is None or not self._run_lock.acquire(blocking=False):
            return
        try:
            while True:
                t = self.book.next_ready()
                if t is None:
                    break
                self.on_cycle(t)
                self.book.done(t)
        finally:
            self._run_lock.release()
        if self.book.next_ready() is not None:  # completed while the lock was being released
            self.advance()

    def _watch(self) -> None:
        import time

        while self._running and self.node.ok():
            t = self.book.pending()
            if t is None:
                time.sleep(0.05)
                continue
            if self.book.wait(t, self.timeout):
                self.advance()
                time.sleep(0.001)
                continue
            if self.book.pending() != t:  # run meanwhile
                continue
            self.node.warn(f"{self.name}: paced: cycle {t:.3f} s still waits for {self.book.missing(t)} after "
                           f"{self.timeout:g} s: running it without ({self.book.timeouts} timeouts)", throttle=5.0)
            self.book.give_up(t)
            with self._run_lock:
                if self.book.pending() == t:
                    self.on_cycle(t)
                    self.book.done(t)
            self.advance()

    def wait(self, t: float) -> bool:
        """Block until cycle ``t``'s inputs are in; after the timeout warn, take what came and go on (False)."""
        if self.book.wait(t, self.timeout):
            return True
        self.node.warn(f"{self.name}: paced: cycle {t:.3f} s still waits for {self.book.missing(t)} after "
                       f"{self.timeout:g} s: going on without it ({self.book.timeouts} timeouts)", throttle=5.0)
        self.book.give_up(t)
        return False
