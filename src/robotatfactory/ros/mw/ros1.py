"""The node interface on ROS 1 (rospy, Debian's ros_comm 1.15). rospy has one node per process: a
:class:`Ros1Node` is a view of it. Master handling (a private roscore, noticing a restarted master) is here
too: ROS 2 has no master."""
from __future__ import annotations

import functools
import os
import sys
import threading
import time
import warnings
from typing import Any, Callable

import rospy

from .base import Node, Publisher, QoS, RawTopic, flatten, throttled
from .local import LocalBus, LocalPublisher, LocalSubscription

NAME = "ros1"
MASTER_RESTARTED = 4  # exit code of a node whose ROS master restarted under it


def time_msg(ns: int) -> rospy.Time:
    ns = int(ns)
    return rospy.Time(ns // 1_000_000_000, ns % 1_000_000_000)


def duration_msg(s: float) -> rospy.Duration:
    return rospy.Duration.from_sec(s)


def diag_level(level: int) -> int:
    return int(level)


def srv_types():
    """The package's own service classes (generated from srv/*.srv by srv/generate.py)."""
    from ... import srv

    return srv


def standard_sim_types():
    """ROS 2's simulation_interfaces: None on ROS 1 (the package's own sim/* services serve instead)."""
    return None


def serialize(msg) -> bytes:
    """A ROS 1 message object as it goes over the wire (and into a ROS 1 bag)."""
    import io

    buf = io.BytesIO()
    msg.serialize(buf)
    return buf.getvalue()


_BUILTIN_EXACT = {"bool", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64", "float64",
                  "string", "time", "duration", "byte", "char"}


@functools.lru_cache(maxsize=None)
def wire_exact(type_name: str) -> bool:
    """True when a message of this type comes out of rospy's serialization as it went in: no ``float32``
    anywhere in it (a Python float is a float64; the wire rounds it to 32 bits)."""
    import roslib.message

    base = type_name.split("[", 1)[0]
    if base in _BUILTIN_EXACT:
        return True
    if base == "float32":
        return False
    if base == "Header":
        base = "std_msgs/Header"
    cls = roslib.message.get_message_class(base)
    return cls is not None and all(wire_exact(t) for t in cls._slot_types)


def wire_copy(msg_type) -> Callable | None:
    """For the in-process path (:mod:`.local`): a function giving a message as a subscriber in another process
    would receive it (serialized and read back) when that differs from the object itself (``float32`` fields,
    e.g. LaserScan's ranges), else None: composed nodes see the values separate nodes see."""
    if wire_exact(msg_type._type):
        return None
    return lambda msg: msg_type().deserialize(serialize(msg))


def require_master(hint: str) -> str:
    """The ROS master's URI; ConfigError ``no ROS master at URI: <hint>`` when none answers."""
    import rosgraph

    if not rosgraph.is_master_online():
        from ...errors import ConfigError

        raise ConfigError(f"no ROS master at {rosgraph.get_master_uri()}: {hint}")
    return rosgraph.get_master_uri()


class _Pub(Publisher):
    def __init__(self, pub: rospy.Publisher):
        self._pub = pub

    def publish(self, msg) -> None:
        self._pub.publish(msg)

    def subscriber_count(self) -> int:
        return self._pub.get_num_connections()


class _Both:
    """A composed node's subscription: rospy's (other processes' publishers) and the bus's (this process's)."""

    def __init__(self, sub: rospy.Subscriber, local: LocalSubscription):
        self.sub, self.local = sub, local


class Ros1Node(Node):
    """The process's rospy node, or (``component``) one of the nodes composed in it (:func:`run_nodes`): then
    the name and the private namespace (parameters, ``~`` names) are the component's (its log lines go to the
    process's log, as rospy has one), and its topics between the components of the process go through ``bus``
    (:mod:`.local`). ``tf`` shares the TF
    publishers of the process (rospy has one publisher per topic and process: one latched ``/tf_static``)."""

    middleware = NAME

    def __init__(self, component: str | None = None, bus: LocalBus | None = None, tf: "Ros1Node | None" = None):
        self._static: dict[str, Any] = {}
        self._static_pub = None
        self._tf_pub = None
        self._lock = threading.Lock()
        self._bus = bus
        self._tf = tf
        self._name = None
        if component is not None:
            ns = self.namespace.rstrip("/")
            self._name = f"{ns}/{component}"

    @property
    def name(self) -> str:
        return self._name or rospy.get_name()

    @property
    def namespace(self) -> str:
        return rospy.get_namespace().rstrip("/") or "/"

    def resolve(self, name: str) -> str:
        if self._name is not None and name.startswith("~"):  # the component's private name, not the process's
            return f"{self._name}/{name[1:].lstrip('/')}"
        return rospy.resolve_name(name)

    def sibling(self, name: str) -> "Ros1Node":
        return Ros1Node(name, self._bus, tf=self._tf or self)

    def publisher(self, topic, msg_type, qos=QoS.RELIABLE, depth=10) -> Publisher:
        kw: dict = {"queue_size": depth}
        if qos is QoS.LATCHED:
            kw.update(latch=True, queue_size=max(1, depth))
        elif qos is QoS.CONTROL:
            kw.update(queue_size=1, tcp_nodelay=True)
        elif qos is QoS.SYNCHRONOUS:
            kw.update(queue_size=None)  # written in the publishing thread: the control path
        topic = self.resolve(topic)
        with warnings.catch_warnings():  # rospy warns about queue_size=None: here it is deliberate
            warnings.simplefilter("ignore", SyntaxWarning)
            pub = _Pub(rospy.Publisher(topic, msg_type, **kw))
        return pub if self._bus is None else self._bus.publisher(topic, pub, qos, wire_copy(msg_type))

    def subscribe(self, topic, msg_type, callback, qos=QoS.RELIABLE, depth=10, large=False):
        kw: dict = {"queue_size": depth, "tcp_nodelay": qos in (QoS.CONTROL, QoS.SENSOR, QoS.SYNCHRONOUS)}
        if large:
            kw["buff_size"] = 1 << 24
        topic = self.resolve(topic)
        # composed: the other processes' publishers through rospy (the process's own are left out: _own_uri_out),
        # the components' through the bus
        bus = self._bus if topic not in _ROSPY_OWN else None
        if bus is not None:
            _BUS_TOPICS.add(topic)
        sub = rospy.Subscriber(topic, msg_type, callback, **kw)
        if bus is None:
            return sub
        return _Both(sub, bus.subscribe(topic, callback, depth))

    def service(self, name, srv_type, handler):
        resp_cls = srv_type._response_class
        return rospy.Service(name, srv_type, lambda req: handler(req, resp_cls()))

    def call(self, name, srv_type, /, timeout=5.0, **fields):
        try:
            rospy.wait_for_service(name, timeout=timeout)
        except rospy.ROSException:
            raise TimeoutError(f"the service {name} is not offered within {timeout} s") from None
        return rospy.ServiceProxy(name, srv_type)(srv_type._request_class(**fields))

    def timer(self, period, callback):
        return rospy.Timer(rospy.Duration.from_sec(period), lambda _ev: callback())

    def topic_types(self) -> dict[str, str]:
        return dict(rospy.get_published_topics())

    def subscribe_raw(self, topic, msg_type, callback):
        def on_message(msg) -> None:
            data = getattr(msg, "_buff", None)
            if data is None:  # rospy shares one subscription per topic: on /clock its own typed one
                data = serialize(msg)
                info = RawTopic(type=msg._type, definition=msg._full_text, digest=msg._md5sum)
            else:
                h = msg._connection_header
                info = RawTopic(type=h["type"], definition=h["message_definition"], digest=h["md5sum"],
                                latched=h.get("latching") == "1")
            callback(data, info)

        topic = self.resolve(topic)
        bus = self._bus if topic not in _ROSPY_OWN else None
        if bus is not None:
            _BUS_TOPICS.add(topic)
        sub = rospy.Subscriber(topic, rospy.AnyMsg, on_message, queue_size=1000, buff_size=2 ** 24, tcp_nodelay=True)
        if bus is None:
            return sub, None

        def on_local(msg) -> None:  # a component's message, an object: serialized here, its latching the bus's
            callback(serialize(msg), RawTopic(type=msg._type, definition=msg._full_text, digest=msg._md5sum,
                                              latched=bus.latched(topic)))

        return _Both(sub, bus.subscribe(topic, on_local, 1000)), None

    def close(self, handle) -> None:
        if handle is None:
            return
        if isinstance(handle, _Both):
            handle.local.close()
            handle = handle.sub
        if isinstance(handle, LocalPublisher):
            handle.bus.unpublish(handle)
            handle = handle.inner
        inner = handle._pub if isinstance(handle, _Pub) else handle
        if isinstance(inner, (rospy.Timer, rospy.Service)):
            stop = inner.shutdown
        elif isinstance(inner, (rospy.Subscriber, rospy.Publisher)):
            stop = inner.unregister
        else:
            raise TypeError(f"close: not a subscription, publisher, service or timer: {handle!r}")
        try:
            stop()  # twice: rospy's own flags make the second call do nothing
        except Exception:  # noqa: BLE001 - already gone with the node (after shutdown)
            pass

    def send_tf(self, transforms) -> None:
        from tf2_msgs.msg import TFMessage

        if self._tf is not None:
            return self._tf.send_tf(transforms)
        if self._tf_pub is None:
            with self._lock:
                if self._tf_pub is None:  # (composed: through the bus too, so a component's recorder has it)
                    self._tf_pub = self.publisher("/tf", TFMessage, QoS.RELIABLE, 100)
        self._tf_pub.publish(TFMessage(transforms=list(transforms)))

    def send_static_tf(self, transforms) -> None:
        from tf2_msgs.msg import TFMessage

        if self._tf is not None:
            return self._tf.send_static_tf(transforms)
        with self._lock:
            if self._static_pub is None:
                self._static_pub = self.publisher("/tf_static", TFMessage, QoS.LATCHED, 100)
            for t in transforms:
                self._static[t.child_frame_id] = t
            self._static_pub.publish(TFMessage(transforms=list(self._static.values())))

    def now(self):
        return rospy.Time.now()

    def params(self, defaults=None, describe=None, given=None) -> dict:
        p = rospy.get_param(self._name or "~", {})
        return p if isinstance(p, dict) else {}

    def log(self, level, text, throttle=0.0) -> None:
        fn = {"debug": rospy.logdebug, "info": rospy.loginfo, "warn": rospy.logwarn, "error": rospy.logerr,
              "fatal": rospy.logfatal}[level]
        if throttle > 0:
            throttled(fn, throttle, text)
        else:
            fn(text)

    def ok(self) -> bool:
        return not rospy.is_shutdown()

    def shutdown(self, reason: str = "") -> None:
        rospy.signal_shutdown(reason or "shutdown")

    def spin(self) -> None:
        rospy.spin()

    def set_executor(self, kind: str) -> None:
        pass  # rospy: a thread per subscription, nothing to choose

    def spin_in_background(self, name: str) -> None:
        return None  # rospy's own threads serve the callbacks

    def finish(self, reason: str = "", spinner: threading.Thread | None = None) -> None:
        if not rospy.is_shutdown():
            self.shutdown(reason)
        if spinner is not None:
            spinner.join(5.0)


# ---- the process's node ---------------------------------------------------------------------------------

def loopback_ros_default() -> None:
    """With the master on this machine and neither ROS_IP nor ROS_HOSTNAME set, let this node's XML-RPC and
    TCPROS servers listen on 127.0.0.1 (rospy binds every interface otherwise). Before ``init_node``."""
    from urllib.parse import urlparse

    if os.environ.get("ROS_IP") or os.environ.get("ROS_HOSTNAME"):
        return
    host = urlparse(os.environ.get("ROS_MASTER_URI", "http://localhost:11311/")).hostname or ""
    if host == "localhost" or host.startswith("127."):
        os.environ["ROS_IP"] = "127.0.0.1"


def init_node(name: str, argv: list[str] | None = None, anonymous: bool = False, signals: bool = True,
              namespace: str = "", bus: LocalBus | None = None) -> Ros1Node:
    """``rospy.init_node`` (once per process) and the node's view; ``bus``: the process's components' bus
    (:func:`run_nodes`), which the process's own publishers (the TF of every component's ``send_tf``) use too."""
    loopback_ros_default()
    ns = namespace.strip("/")
    if ns:
        # rospy takes its namespace from ROS_NAMESPACE / __ns when it is imported; an __ns given to init_node
        # later is not read (rospy/names.py sets _caller_id at import, init_node resolves the node name
        # against it): set it here
        os.environ["ROS_NAMESPACE"] = f"/{ns}"
        rospy.names._set_caller_id(f"/{ns}/unnamed")
        argv = list(argv or [sys.argv[0]]) + [f"__ns:=/{ns}"]
    rospy.init_node(name, argv=argv if argv is not None else sys.argv, anonymous=anonymous,
                    disable_signals=not signals)
    return Ros1Node(bus=bus)


def myargv(argv: list[str]) -> list[str]:
    """The command line without ROS 1's remapping arguments (``name:=value``)."""
    return rospy.myargv(argv)


def master_pid() -> int | None:
    """The ROS master's process id, or None when no master answers (read before ``init_node``, so that a
    master restarted while the node starts up is noticed by :func:`watch_master`)."""
    import rosgraph

    try:
        return int(rosgraph.Master("/raf_master_pid").getPid())
    except Exception:  # noqa: BLE001 - no master (reported elsewhere)
        return None


def watch_master(who: str, period: float = 1.0, pid0: int | None = None) -> dict:
    """Watch the ROS master from a daemon thread: when it restarts (a new process answers at the same URI),
    rospy cannot re-register this node's publishers and subscribers with it, so the node would go on deaf
    and mute. Log a clear message and shut the node down instead (roslaunch ``respawn="true"`` or the user
    starts it again). ``pid0``: the master's pid read before the node registered (default: read now).
    Returns a dict whose ``"restarted"`` is set True when that happened."""
    import rosgraph

    state = {"restarted": False}
    m = rosgraph.Master(rospy.get_name() or f"/raf_{who}")
    if pid0 is None:
        try:
            pid0 = m.getPid()
        except Exception:  # noqa: BLE001 - no master to watch (it will be reported elsewhere)
            return state

    def loop():
        lost = False
        while not rospy.is_shutdown():
            time.sleep(period)
            try:
                pid = m.getPid()
            except Exception:  # noqa: BLE001 - master down: wait for it to come back
                if not lost:
                    rospy.logwarn(f"{who}: the ROS master at {rosgraph.get_master_uri()} does not answer; "
                                  "waiting for it (topics already connected keep flowing)")
                lost = True
                continue
            if pid != pid0:
                state["restarted"] = True
                rospy.logfatal(f"{who}: the ROS master restarted (pid {pid0} -> {pid}); rospy cannot register this "
                               "node's topics with the new master, so the node exits (exit code "
                               f"{MASTER_RESTARTED}): start it again, or use respawn=\"true\" under roslaunch")
                rospy.signal_shutdown("the ROS master restarted")
                return
            if lost:
                rospy.loginfo(f"{who}: the ROS master answers again (same process)")
                lost = False

    threading.Thread(target=loop, name=f"raf-{who}-master-watch", daemon=True).start()
    return state


def run_node(args, who: str, params: dict, make_node: Callable[[Node], object],
             started: Callable[[object], str]) -> int:
    """Run one node from the command line until Ctrl-C (see :func:`robotatfactory.ros.cli.run_node`)."""
    from ..master import ensure_master

    master = ensure_master(args.roscore, who)
    import rosgraph

    ns = args.ns.strip("/")
    path = f"/{ns}/{args.name}" if ns else f"/{args.name}"
    m = rosgraph.Master(f"/raf_{who}_cli")
    if not args.no_sim_time:
        m.setParam("/use_sim_time", True)
    for key, value in params.items():
        m.setParam(f"{path}/{key}" if key else path, list(value) if isinstance(value, tuple) else value)
    loopback_ros_default()
    pid0 = master_pid()
    node = init_node(args.name, argv=[sys.argv[0]], namespace=ns)
    obj = make_node(node)
    print(f"raf {who}: {started(obj)}", flush=True)
    watch = watch_master(f"raf {who}", pid0=pid0)
    try:
        rospy.spin()
    finally:
        obj.stop()
        if master is not None:
            master.stop()
    return MASTER_RESTARTED if watch["restarted"] else 0


def spin_node(name: str, make_node: Callable[[Node], object], argv: list[str] | None = None) -> int:
    """A node's ``main`` under roslaunch: init, build from the private parameters, spin, stop.

    A bad parameter (ConfigError from ``make_node``) is logged as fatal and ends the node with exit code 2.
    """
    from ...errors import ConfigError

    loopback_ros_default()
    pid0 = master_pid()
    node = init_node(name, argv=argv if argv is not None else sys.argv)
    try:
        obj = make_node(node)
    except ConfigError as e:
        rospy.logfatal(f"{name}: {e}")
        return 2
    watch = watch_master(name, pid0=pid0)
    rospy.spin()
    obj.stop()
    return MASTER_RESTARTED if watch["restarted"] else 0


#: topics a component of this process subscribes to through the bus (:mod:`.local`): rospy leaves this
#: process's own publishers of them out (:func:`_own_uri_out`)
_BUS_TOPICS: set[str] = set()
#: topics rospy itself subscribes to in every process (its clock under ``use_sim_time``): never on the bus, a
#: component hears them through rospy as rospy's own subscription does (one subscription per topic and
#: process: on the bus as well, a component would hear each message twice)
_ROSPY_OWN = frozenset({"/clock"})


def _own_uri_out() -> None:
    """rospy connects a subscriber to every publisher of its topic, its own process's too (through a socket,
    the message serialized and read back). In a composed process the components' messages go through the
    bus (:mod:`.local`): for the topics the bus carries (:data:`_BUS_TOPICS`), leave this process out of every
    publisher list rospy acts on (the initial one and the master's updates both pass
    ``RegManager.publisher_update``). rospy's own subscriptions (``/clock`` under ``use_sim_time``) keep it:
    the process's clock is the bridge's."""
    from rospy.impl.registration import RegManager

    if getattr(RegManager.publisher_update, "_raf_own_out", False):
        return
    original = RegManager.publisher_update

    def publisher_update(self, resolved_name, uris):
        if resolved_name in _BUS_TOPICS:
            own = rospy.core.get_node_uri()
            uris = [u for u in uris if u != own]
        return original(self, resolved_name, uris)

    publisher_update._raf_own_out = True
    RegManager.publisher_update = publisher_update


def _reported(what: str, action: Callable[[], None]) -> None:
    """``action()``, an exception from it printed and not raised: a component's failure to stop or close
    leaves the others to stop and close."""
    try:
        action()
    except Exception as e:  # noqa: BLE001 - reported; the others still stop
        print(f"raf compose: {what} failed: {type(e).__name__}: {e}", file=sys.stderr, flush=True)


def run_nodes(args, plans: list) -> int:
    """Several nodes as components of one process (see :func:`robotatfactory.ros.cli.run_nodes`): one rospy
    node (``args.name``), each plan's node a :class:`Ros1Node` component of it with the plan's name and
    parameters, messages between them in-process (:mod:`.local`). At the end every node started is stopped
    and every plan closed (:attr:`~robotatfactory.ros.cli.NodePlan.close`), whatever one of them raised."""
    from ..master import ensure_master

    master = ensure_master(args.roscore, "compose")
    import rosgraph

    ns = args.ns.strip("/")
    m = rosgraph.Master("/raf_compose_cli")
    if not args.no_sim_time:
        m.setParam("/use_sim_time", True)
    for plan in plans:
        path = f"/{ns}/{plan.name}" if ns else f"/{plan.name}"
        for key, value in plan.params.items():
            m.setParam(f"{path}/{key}" if key else path, list(value) if isinstance(value, tuple) else value)
    loopback_ros_default()
    pid0 = master_pid()
    _own_uri_out()
    bus = LocalBus(on_error=lambda text: rospy.logerr(f"{args.name}: {text}"))
    # on the bus too: the process's TF publishers (every component's send_tf) reach the components
    process = init_node(args.name, argv=[sys.argv[0]], namespace=ns, bus=bus)
    objs = []
    try:
        for plan in plans:
            obj = plan.make_node(Ros1Node(plan.name, bus, tf=process))
            objs.append((plan, obj))
            print(f"raf {plan.who}: {plan.started(obj)}", flush=True)
        watch = watch_master(f"raf compose {args.name}", pid0=pid0)
        rospy.spin()
    finally:
        try:
            for plan, obj in reversed(objs):  # each one stopped, whatever the one before did
                _reported(f"stopping {plan.who}", obj.stop)
            for plan in reversed(plans):  # what a plan holds open (record's bag), its node started or not
                if plan.close is not None:
                    _reported(f"closing {plan.who}", plan.close)
            c = bus.counts()
            print(f"raf compose: {len(plans)} nodes; in-process messages {c['delivered']} delivered, "
                  f"{c['dropped']} dropped (a full queue)", flush=True)
        finally:
            if master is not None:
                master.stop()
    return MASTER_RESTARTED if watch["restarted"] else 0


def flat_params(tree: dict) -> dict:
    """ROS 1 parameter names of a nested tree (``udp/port``)."""
    return flatten(tree, "/")
