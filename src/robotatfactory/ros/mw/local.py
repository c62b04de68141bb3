"""The in-process message path of composed nodes (``raf compose``): what nodelets are to ROS 1 and composable
nodes with intra-process communication are to ROS 2, for the nodes of this project.

Several nodes (components) in one process each publish and subscribe as usual through their
:class:`~.base.Node`; the implementation routes a topic's messages between the components of the process
through one :class:`LocalBus`: a published message is handed, as the same object, to every local subscription
of its topic (no serialization, no socket; a type the wire would change, one with ``float32`` fields, is first
made what the wire makes of it: ``wire``), and goes over the middleware only to other processes'
subscribers. A local subscription is served as the middleware serves one: by a thread of its own, from a
queue of ``depth`` messages (the oldest dropped when it is full, and counted), so a slow subscriber never
holds up the publisher. A latched topic's last message (per publisher) reaches a local subscription made
later, as a latched connection gives it.

The rules for a composed node: a received message is shared with the other local subscribers and must not be
modified; a published message must not be modified after ``publish``. The nodes of this project build each
message anew.

Plain Python, no middleware import: :mod:`.ros1` wires it in.
"""
from __future__ import annotations

import queue
import threading
from typing import Any, Callable

from .base import Publisher, QoS


_CLOSE = object()  # the sentinel that ends a subscription's thread


class LocalSubscription:
    """One component's subscription to a topic of the bus: a queue and the thread that calls ``callback``.

    The queue is a ``queue.SimpleQueue`` (put and get in C: a Python ``Condition`` per message cost about a
    seventh of a composed paced run's GIL time); the publisher keeps it to ``depth`` by taking the oldest out."""

    def __init__(self, bus: "LocalBus", topic: str, callback: Callable[[Any], None], depth: int,
                 on_error: Callable[[str], None]):
        self.bus, self.topic, self.callback = bus, topic, callback
        self.queue: queue.SimpleQueue = queue.SimpleQueue()
        self.depth = max(1, int(depth))
        self.dropped = 0  # messages dropped because the queue was full (the oldest first, as rospy does)
        self.delivered = 0  # messages handed to the callback (counted before it runs, whether it raises or not)
        self._closed = False
        # the counts against close(): no message is counted once it has set _closed, so the counts that
        # LocalBus.remove takes then are final (a plain lock, taken once a message and on a drop)
        self._lock = threading.Lock()
        self._on_error = on_error
        self._thread = threading.Thread(target=self._serve, name=f"raf-local{topic}", daemon=True)
        self._thread.start()

    def put(self, msg) -> None:
        if self._closed:
            return
        while self.queue.qsize() >= self.depth:
            with self._lock:
                if self._closed:
                    return
                try:
                    self.queue.get_nowait()
                    self.dropped += 1
                except queue.Empty:  # the subscription's thread took it meanwhile
                    break
        self.queue.put(msg)

    def _serve(self) -> None:
        while True:
            msg = self.queue.get()
            if msg is _CLOSE:
                return
            with self._lock:  # counted before the callback: one that closes this subscription is counted too
                if self._closed:
                    return
                self.delivered += 1
            try:
                self.callback(msg)
            except Exception as e:  # noqa: BLE001 - a callback's error is logged, as the middleware does
                self._on_error(f"{self.topic}: callback error: {type(e).__name__}: {e}")

    def close(self) -> None:
        with self._lock:  # (released before the bus's lock is taken: a latched publish holds that, then this)
            self._closed = True
        self.queue.put(_CLOSE)
        self.bus.remove(self)


class LocalPublisher(Publisher):
    """A component's publisher: every local subscription of the topic gets the message, and ``inner`` (the
    middleware's publisher) sends it to the subscribers of other processes."""

    def __init__(self, bus: "LocalBus", topic: str, inner: Publisher, latched: bool,
                 wire: Callable[[Any], Any] | None = None):
        self.bus, self.topic, self.inner, self.latched, self.wire = bus, topic, inner, latched, wire
        self.last = None  # a latched topic's last message

    def publish(self, msg) -> None:
        self.bus.deliver(self, msg)
        self.inner.publish(msg)

    def subscriber_count(self) -> int:
        return len(self.bus.subscriptions(self.topic)) + self.inner.subscriber_count()


class LocalBus:
    """The topics of one process's components, by resolved name."""

    def __init__(self, on_error: Callable[[str], None] = lambda text: None):
        self._lock = threading.Lock()
        self._subs: dict[str, tuple[LocalSubscription, ...]] = {}
        self._pubs: dict[str, list[LocalPublisher]] = {}
        self.on_error = on_error
        self._closed = {"delivered": 0, "dropped": 0}  # the counts of the subscriptions closed so far

    def publisher(self, topic: str, inner: Publisher, qos: QoS,
                  wire: Callable[[Any], Any] | None = None) -> LocalPublisher:
        """``wire(msg)``: the message as the middleware would deliver it, when that differs from the object
        (the middleware's ``wire_copy``), so that a local subscriber sees what a remote one sees."""
        pub = LocalPublisher(self, topic, inner, latched=qos is QoS.LATCHED, wire=wire)
        with self._lock:
            self._pubs.setdefault(topic, []).append(pub)
        return pub

    def subscribe(self, topic: str, callback: Callable[[Any], None], depth: int) -> LocalSubscription:
        sub = LocalSubscription(self, topic, callback, depth, self.on_error)
        with self._lock:  # (a latched publish waits: its message comes either as the latch or live, once)
            self._subs[topic] = self._subs.get(topic, ()) + (sub,)
            for p in self._pubs.get(topic, ()):
                if p.latched and p.last is not None:
                    sub.put(p.last)
        return sub

    def subscriptions(self, topic: str) -> tuple[LocalSubscription, ...]:
        return self._subs.get(topic, ())  # (a tuple replaced whole under the lock: read without it)

    def deliver(self, pub: LocalPublisher, msg) -> None:
        """``msg``, published by ``pub``, to every local subscription of its topic (as ``pub.wire`` makes it).
        A latched topic's message is also kept as ``pub.last``."""
        if pub.latched:  # the latch and the delivery at once: a subscription made meanwhile gets one or the other
            local = pub.wire(msg) if pub.wire is not None else msg
            with self._lock:
                pub.last = local
                for sub in self.subscriptions(pub.topic):
                    sub.put(local)
        else:
            subs = self.subscriptions(pub.topic)
            local = pub.wire(msg) if pub.wire is not None and subs else msg
            for sub in subs:
                sub.put(local)

    def unpublish(self, pub: LocalPublisher) -> None:
        """``pub`` is closed: its latched message no longer reaches new subscriptions."""
        with self._lock:
            self._pubs[pub.topic] = [p for p in self._pubs.get(pub.topic, ()) if p is not pub]

    def latched(self, topic: str) -> bool:
        """True when a component of this process publishes ``topic`` latched."""
        return any(p.latched for p in self._pubs.get(topic, ()))

    def remove(self, sub: LocalSubscription) -> None:
        """``sub`` is closed: it hears no more, and its counts are kept for :meth:`counts`."""
        with self._lock:
            group = self._subs.get(sub.topic, ())
            if sub in group:
                self._subs[sub.topic] = tuple(s for s in group if s is not sub)
                self._closed["delivered"] += sub.delivered
                self._closed["dropped"] += sub.dropped

    def counts(self) -> dict[str, int]:
        """Messages delivered and dropped over every local subscription, closed ones included."""
        with self._lock:
            subs = [s for group in self._subs.values() for s in group]
            return {k: self._closed[k] + sum(getattr(s, k) for s in subs) for k in ("delivered", "dropped")}
