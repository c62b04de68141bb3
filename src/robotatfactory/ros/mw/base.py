"""The node interface both middlewares implement (:mod:`.ros1`, :mod:`.ros2`), and what they share.

Nodes state *intents*, each middleware maps them to its own means:

==============  =======================================  ==================================================
QoS             ROS 1 (rospy)                            ROS 2 (rclpy)
==============  =======================================  ==================================================
``SENSOR``      queue ``depth``                          best effort, volatile, keep last ``depth``
``RELIABLE``    queue ``depth``                          reliable, volatile, keep last ``depth``
``CONTROL``     queue 1, ``tcp_nodelay``                 reliable, keep last 1 (commands: latest wins)
``LATCHED``     ``latch=True``                           reliable, transient local, keep last 1 (the map,
                                                         ``/tf_static``)
``SYNCHRONOUS`` ``queue_size=None``: written in the      reliable, keep last ``depth`` (rclpy's publish is
                caller's thread (the control path)       synchronous already)
==============  =======================================  ==================================================

Stamps are the middleware's own time message (``rospy.Time`` / ``builtin_interfaces/Time``); build them with
the implementation's ``time_msg(ns)`` and read them with ``stamp_ns(stamp)`` (which reads either kind).

An implementation module also provides (module level): ``NAME``, ``time_msg(ns)``, ``duration_msg(s)``,
``diag_level(level)``, ``srv_types()``, ``standard_sim_types()`` (ROS 2's simulation_interfaces, or None),
``serialize(msg) -> bytes`` (a message as it goes over the wire: ROS 1's serialization or ROS 2's CDR),
``require_master(hint) -> str | None`` (ROS 1: ConfigError unless a master answers, else its URI; ROS 2 has
none: None), ``init_node(...) -> Node``, ``run_node(...)`` (a node from the command line) and
``spin_node(...)`` (a node's ``main`` under a launch file). What can be asked by a middleware's name without
importing it (``has_master``, ``bag_format``) is in :mod:`robotatfactory.ros.mw` itself.
"""
from __future__ import annotations

import enum
import threading
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Callable


class QoS(enum.Enum):
    SENSOR = "sensor"
    RELIABLE = "reliable"
    CONTROL = "control"
    LATCHED = "latched"
    SYNCHRONOUS = "synchronous"


# diagnostic_msgs/DiagnosticStatus levels as plain ints (ROS 2 spells them as bytes: see diag_level)
OK, WARN, ERROR, STALE = 0, 1, 2, 3


def stamp_ns(stamp) -> int:
    """Nanoseconds of a ROS 1 (``secs``/``nsecs``) or ROS 2 (``sec``/``nanosec``) time message."""
    if hasattr(stamp, "nanosec"):
        return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return int(stamp.secs) * 1_000_000_000 + int(stamp.nsecs)


def stamp_s(stamp) -> float:
    return stamp_ns(stamp) * 1e-9


def level_int(level) -> int:
    """A DiagnosticStatus level (int in ROS 1, one byte in ROS 2) as an int."""
    return level[0] if isinstance(level, (bytes, bytearray)) else int(level)


def flatten(tree: dict, sep: str, prefix: str = "") -> dict:
    """``{"udp": {"port": 1}}`` -> ``{"udp<sep>port": 1}``."""
    out = {}
    for k, v in tree.items():
        key = f"{prefix}{sep}{k}" if prefix else str(k)
        if isinstance(v, dict) and v:
            out.update(flatten(v, sep, key))
        else:
            out[key] = v
    return out


def typed_like(value, default):
    """``value`` with the type of ``default`` where ROS 2 would otherwise see another type: a whole number
    where the default is a real becomes a real (also inside lists: ``[1, 0.5]`` -> ``[1.0, 0.5]``). Anything
    else is returned as it is (the node's validation judges it). ROS 2 types parameters strictly (a real
    parameter rejects ``3``); this is the one place of that rule (:meth:`Node.params`, the ROS 2 parameter
    files of :mod:`..params2`)."""
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if isinstance(default, (list, tuple)) and isinstance(value, (list, tuple)):
        if any(isinstance(d, float) for d in default) or any(isinstance(v, float) for v in value):
            return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
        return list(value)
    return value


def typed_tree(values: dict, defaults: dict) -> dict:
    """A nested ``values`` tree with each leaf :func:`typed_like` the same leaf of ``defaults`` (keys the
    defaults lack are kept as they are)."""
    out = {}
    for k, v in values.items():
        d = defaults.get(k) if isinstance(defaults, dict) else None
        if isinstance(v, dict):
            out[k] = typed_tree(v, d if isinstance(d, dict) else {})
        else:
            out[k] = typed_like(v, d)
    return out


def unflatten(flat: dict, sep: str) -> dict:
    out: dict = {}
    for key, v in flat.items():
        parts = key.split(sep)
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = v
    return out


_last_throttled: dict = {}


def throttled(fn: Callable[[str], None], period: float, text: str) -> None:
    """``fn(text)`` at most once per ``period`` wall seconds per call site (the function and the text's first
    40 characters): the same rule on both middlewares."""
    import time

    key = (fn, text[:40])
    now = time.monotonic()
    if now - _last_throttled.get(key, -1e18) >= period:
        _last_throttled[key] = now
        fn(text)


@dataclass
class RawTopic:
    """What a raw subscription (:meth:`Node.subscribe_raw`) tells of its topic: what a bag's connection record
    needs."""

    type: str  #: the message type as the middleware names it (``nav_msgs/Odometry``, ``nav_msgs/msg/Odometry``)
    definition: str | None = None  #: ROS 1: the message definition (from the connection header)
    digest: str | None = None  #: ROS 1: its MD5 sum
    latched: bool = False  #: ROS 1: the publisher latches
    offered_qos: list = field(default_factory=list)  #: ROS 2: each publisher's QoS profile (rclpy ``QoSProfile``)
    qos: str = ""  #: ROS 2: the subscription's QoS in words (``reliable, transient_local``), for logs


class Publisher(ABC):
    @abstractmethod
    def publish(self, msg) -> None: ...

    @abstractmethod
    def subscriber_count(self) -> int: ...


class Node(ABC):
    """One node of one middleware. Topic and service names resolve against the node's namespace (a
    leading ``/`` makes them global, ``~`` private), as in both ROS generations."""

    middleware: str = ""

    # -- identity ------------------------------------------------------------------------------------
    @property
    @abstractmethod
    def name(self) -> str:
        """The fully qualified node name (``/robot1/raf_bridge``)."""

    @property
    @abstractmethod
    def namespace(self) -> str:
        """The node's namespace (``/`` or ``/robot1``)."""

    @abstractmethod
    def resolve(self, name: str) -> str:
        """A topic or service name resolved against the node's namespace."""

    # -- communication -------------------------------------------------------------------------------
    @abstractmethod
    def publisher(self, topic: str, msg_type, qos: QoS = QoS.RELIABLE, depth: int = 10) -> Publisher: ...

    @abstractmethod
    def subscribe(self, topic: str, msg_type, callback: Callable[[Any], None], qos: QoS = QoS.RELIABLE,
                  depth: int = 10, large: bool = False):
        """Subscribe; ``large``: messages of megabytes (images: ROS 1 grows its receive buffer)."""

    @abstractmethod
    def service(self, name: str, srv_type, handler: Callable[[Any, Any], Any]):
        """Serve ``name``; ``handler(request, response)`` fills and returns the response. Each call runs in a
        thread of its own (rospy's way; on ROS 2 a worker thread answers it), so a handler that waits never
        holds up the node's other callbacks."""

    @abstractmethod
    def call(self, name: str, srv_type, /, timeout: float = 5.0, **fields):
        """Call the service ``name`` with a request of these fields and return its response; waits up to
        ``timeout`` s for the service to be offered and for its answer (``TimeoutError``). Call it from a
        thread of your own, never from a callback (on ROS 2 the answer comes through this node's executor)."""

    def sibling(self, name: str) -> "Node":
        """Another node ``name`` (same namespace) in this process, beside this one: composed with it as
        :func:`~robotatfactory.ros.cli.run_nodes` composes (its messages to this process's other nodes go
        in-process). ROS 1 only (rospy has one node per process: the new node is a component of it);
        NotImplementedError elsewhere."""
        raise NotImplementedError(f"{self.middleware}: no second node in this process (ROS 1 only)")

    def action_server(self, name: str, action_type, execute: Callable[[Any, Callable, Callable], tuple]):
        """Serve the action ``name``: ``execute(goal, publish_feedback, cancel_requested)`` runs each accepted
        goal in a thread of its own and returns ``(outcome, result)``, outcome one of ``succeeded``,
        ``aborted``, ``canceled``; ``publish_feedback(msg)`` sends feedback, ``cancel_requested()`` is True once
        a client asked to cancel (every cancel request is accepted). ROS 2 only: ROS 1 has no actions in this
        project (``NotImplementedError``)."""
        raise NotImplementedError(f"{self.middleware}: no action servers (ROS 2 only)")

    @abstractmethod
    def timer(self, period: float, callback: Callable[[], None]):
        """Call ``callback()`` every ``period`` seconds of the node's clock (simulation time under sim time)."""

    @abstractmethod
    def topic_types(self) -> dict[str, str]:
        """The topics on the graph now, each with its message type (ROS 1: the master's published topics,
        ``pkg/Type``; ROS 2: every topic the graph lists with a type, ``pkg/msg/Type``, published or not)."""

    @abstractmethod
    def subscribe_raw(self, topic: str, msg_type: str, callback: Callable[[bytes, RawTopic], None]):
        """Subscribe to ``topic`` (of ``msg_type``, as :meth:`topic_types` names it) without deserializing:
        ``callback(data, info)`` gets each message as it came off the wire (ROS 1's serialization, ROS 2's CDR)
        and what it is (:class:`RawTopic`). ROS 1 subscribes with a deep queue (1000, a 16 MB buffer,
        TCP_NODELAY) and reads ``info`` from each message's connection header; ROS 2 with the QoS every
        publisher matches (``ros2 bag record``'s rule: reliable only if all publishers are, transient local
        only if all are; keep last 100) and knows ``info`` from the graph before the first message.

        Returns ``(handle, info)``: ``info`` when known before the first message (ROS 2), else None (ROS 1);
        or None when the topic has no publisher now (ROS 2). Stop it with :meth:`close`."""

    @abstractmethod
    def close(self, handle) -> None:
        """Stop a subscription, publisher, service server or timer this node made (what :meth:`subscribe`,
        :meth:`publisher`, :meth:`service`, :meth:`timer` returned, or the middleware's own object): no more
        callbacks, the graph no longer lists it. ``None``, closing twice or after shutdown do nothing."""

    # -- TF --------------------------------------------------------------------------------------------
    @abstractmethod
    def send_tf(self, transforms: list) -> None:
        """Publish TransformStamped messages on ``/tf``."""

    @abstractmethod
    def send_static_tf(self, transforms: list) -> None:
        """Publish on latched ``/tf_static``; transforms with a child frame sent before replace the old one."""

    # -- time ------------------------------------------------------------------------------------------
    @abstractmethod
    def now(self):
        """The node clock's time as a stamp message (simulation time under sim time; zero before /clock)."""

    def now_s(self) -> float:
        return stamp_s(self.now())

    # -- parameters ------------------------------------------------------------------------------------
    @abstractmethod
    def params(self, defaults: dict | None = None, describe: Callable[[str], tuple] | None = None,
               given: dict | None = None) -> dict:
        """The node's private parameters as a nested dict. ROS 2 declares every leaf of ``defaults`` first
        (``udp.port``; ``describe(flat_name)`` -> (description, (min, max) or None)) so that
        ``ros2 param describe`` shows them, ``given`` (a nested tree the caller sets, e.g. a command line's
        settings) merged over the defaults first: a leaf the defaults lack is declared with its given value.
        A whole number given (in ``given``, an override or a parameter file) where the default is a real
        becomes a real (:func:`typed_like`). ROS 1 reads ``~`` as it is."""

    # -- logging and life --------------------------------------------------------------------------------
    @abstractmethod
    def log(self, level: str, text: str, throttle: float = 0.0) -> None:
        """``level`` in debug, info, warn, error, fatal; ``throttle`` s: at most one such line that often."""

    def info(self, text: str) -> None:
        self.log("info", text)

    def warn(self, text: str, throttle: float = 0.0) -> None:
        self.log("warn", text, throttle)

    def error(self, text: str) -> None:
        self.log("error", text)

    def fatal(self, text: str) -> None:
        self.log("fatal", text)

    @abstractmethod
    def ok(self) -> bool:
        """False once the node is shutting down."""

    @abstractmethod
    def shutdown(self, reason: str = "") -> None: ...

    @abstractmethod
    def spin(self) -> None:
        """Serve callbacks until shutdown."""

    @abstractmethod
    def set_executor(self, kind: str) -> None:
        """What :meth:`spin` serves callbacks with (call before it): ROS 2's executor, ``events``, ``single``
        (one thread, as ``rclpy.spin(node)`` has it) or ``multi`` (default: ``RAF_ROS2_EXECUTOR``, else
        ``events``). rospy serves each subscription from a thread of its own: nothing to choose on ROS 1."""

    @abstractmethod
    def spin_in_background(self, name: str) -> threading.Thread | None:
        """Have this node's callbacks served while the caller goes on: ROS 2 spins the node in a daemon thread
        called ``name`` (returned: hand it to :meth:`finish`); rospy serves callbacks from threads of its own
        already (None)."""

    @abstractmethod
    def finish(self, reason: str = "", spinner: threading.Thread | None = None) -> None:
        """End this node for good, as a process's last use of its middleware (it cannot be used afterwards):
        shut it down (:meth:`shutdown` with ``reason``), wait up to 5 s for ``spinner`` (the thread
        running :meth:`spin`, if any), and release the middleware: ROS 2 destroys the node and shuts rclpy
        down, which a process must do before its interpreter exits (a daemon thread still in rclpy then
        aborts Python); rospy's one node per process ends with the shutdown."""
