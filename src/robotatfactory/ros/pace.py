"""Pace messages over the middleware (see :mod:`robotatfactory.pace`): each node publishes its paces on its
own topic ``pace/<role>`` (relative: each robot's nodes pace among themselves) and subscribes only to the
topics of the nodes it takes inputs from; ``diagnostic_msgs/DiagnosticArray`` with the cycle's stamp in the
header and one status per message: ``name`` the node's role, ``message`` "pace" (or "hello" at the start), one
``KeyValue`` per output (key, messages published so far). (One shared topic would deliver every node's pace
to every node, 16 deliveries a cycle instead of 6: about a quarter of the messages of a paced cycle.)

Start: a message published before its subscriber has been discovered is lost (ROS 2's discovery can take
seconds), and a lost message would cost a timeout and make the run differ. So each node announces itself
(*hello*, on its own pace topic: hearing it shows that the connection which will carry its paces is up) and,
once it has heard the hello of every node it takes inputs from, says it is *ready* on the shared topic
``pace``; the bridge publishes the first frame only when every node of the loop is ready. Pace messages are
latched (a late subscriber still gets them)."""
from __future__ import annotations

import threading
from typing import Callable

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

from ..pace import Pace, PaceBook, PaceCounts
from . import messages as rm
from .mw import QoS

TOPIC = "pace"  # the start's "ready" announcements; the paces of the node with role R are on f"{TOPIC}/{R}"
DEPTH = 100
HELLO, READY = -1.0, -2.0  # Pace.t of the start's announcements (on the wire: stamp 0, message hello / ready)
_KIND = {HELLO: "hello", READY: "ready"}
#: wall s the bridge waits for every node of the loop to be ready before it answers the first paced frame
READY_TIMEOUT = 60.0
#: wall s a paced node waits for a cycle's inputs before it runs the cycle anyway (warned and counted)
TIMEOUT = 5.0


def to_msg(p: Pace) -> DiagnosticArray:
    m = DiagnosticArray()
    m.header.stamp = rm.stamp_s(p.t if p.t not in _KIND else 0.0)
    st = DiagnosticStatus()
    st.level = DiagnosticStatus.OK
    st.name = p.name
    st.message = _KIND.get(p.t, "pace")
    st.values = [KeyValue(key=k, value=str(int(v))) for k, v in sorted(p.counts.items())]
    m.status = [st]
    return m


def from_msg(m: DiagnosticArray) -> list[Pace]:
    t = rm.stamp_to_s(m.header.stamp)
    out = []
    for st in m.status:
        at = {"hello": HELLO, "ready": READY}.get(st.message, t)
        try:
            out.append(Pace(st.name, at, {k: int(v) for k, v in rm.diagnostic_values(st).items()}))
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
        self.upstream = set(needs or ()) | set(behind or ())
        self.heard: set[str] = set()  # nodes whose hello (or ready) came
        self.ready: set[str] = set()  # nodes that said they are ready
        self._ready_cv = threading.Condition()
        self._said_ready = False
        self.pub = node.publisher(f"{TOPIC}/{name}", DiagnosticArray, QoS.LATCHED, DEPTH)
        self.pub_ready = node.publisher(TOPIC, DiagnosticArray, QoS.LATCHED, DEPTH)
        self.subs = [node.subscribe(f"{TOPIC}/{up}", DiagnosticArray, self._on_pace, QoS.LATCHED, DEPTH)
                     for up in sorted(self.upstream)]
        self.sub_ready = node.subscribe(TOPIC, DiagnosticArray, self._on_ready, QoS.LATCHED, DEPTH)
        self.pub.publish(to_msg(Pace(name, HELLO)))
        self._check_ready()
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
        """A message on an upstream node's pace topic: its hello (or, joined late, one of its paces: latched)
        says the connection is up; a pace goes to the book."""
        paces = from_msg(m)
        fresh = [p.name for p in paces if p.name in self.upstream and p.name not in self.heard]
        if fresh:
            with self._ready_cv:
                self.heard.update(fresh)
                self._ready_cv.notify_all()
            self._check_ready()
        if self.book is not None:
            for p in paces:
                if p.t not in _KIND:
                    self.book.paced(p)
        self.advance()

    def _on_ready(self, m: DiagnosticArray) -> None:
        names = [p.name for p in from_msg(m) if p.t == READY]
        if names:
            with self._ready_cv:
                self.ready.update(names)
                self._ready_cv.notify_all()

    def _check_ready(self) -> None:
        with self._ready_cv:
            if self._said_ready or not self.upstream <= self.heard:
                return
            self._said_ready = True
        self.pub_ready.publish(to_msg(Pace(self.name, READY)))

    def wait_ready(self, names, timeout: float = READY_TIMEOUT) -> bool:
        """Block until every node in ``names`` has said it is ready (False after ``timeout`` wall s, warned)."""
        names = set(names)
        with self._ready_cv:
            ok = self._ready_cv.wait_for(lambda: names <= self.ready, timeout)
            missing = sorted(names - self.ready)
        if not ok:
            self.node.warn(f"{self.name}: paced: {', '.join(missing)} not ready after {timeout:g} s: starting anyway")
        return ok

    def advance(self) -> None:
        """Run every cycle that is ready, in order (callbacks of other threads that find the lock taken leave
        it to the one running: it loops until nothing is ready)."""
        if self.on_cycle is None or self.book is None or not self._run_lock.acquire(blocking=False):
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
                self.advance()  # (another thread may be running it: wait for that instead of spinning)
                self.book.wait_done(t, self.timeout)
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
        """Block until cycle ``t``'s inputs are in; after the timeout warn, take what came and go on (False).
        Either way cycle ``t`` is then done: its paces are forgotten (kept, they would pile up for the whole
        run and make every later lookup slower)."""
        ok = self.book.wait(t, self.timeout)
        if not ok:
            self.node.warn(f"{self.name}: paced: cycle {t:.3f} s still waits for {self.book.missing(t)} after "
                           f"{self.timeout:g} s: going on without it ({self.book.timeouts} timeouts)", throttle=5.0)
            self.book.give_up(t)
        self.book.done(t)
        return ok
