"""The node interface on ROS 1 (rospy, Debian's ros_comm 1.15). rospy has one node per process: a
:class:`Ros1Node` is a view of it. Master handling (a private roscore, noticing a restarted master) is here
too: ROS 2 has no master."""
from __future__ import annotations

import os
import sys
import threading
import time
import warnings
from typing import Any, Callable

import rospy

from .base import Node, Publisher, QoS, RawTopic, flatten, throttled

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


class Ros1Node(Node):
    middleware = NAME

    def __init__(self):
        self._static: dict[str, Any] = {}
        self._static_pub = None
        self._tf_pub = None
        self._lock = threading.Lock()

    @property
    def name(self) -> str:
        return rospy.get_name()

    @property
    def namespace(self) -> str:
        return rospy.get_namespace().rstrip("/") or "/"

    def resolve(self, name: str) -> str:
        return rospy.resolve_name(name)

    def publisher(self, topic, msg_type, qos=QoS.RELIABLE, depth=10) -> Publisher:
        kw: dict = {"queue_size": depth}
        if qos is QoS.LATCHED:
            kw.update(latch=True, queue_size=max(1, depth))
        elif qos is QoS.CONTROL:
            kw.update(queue_size=1, tcp_nodelay=True)
        elif qos is QoS.SYNCHRONOUS:
            kw.update(queue_size=None)  # written in the publishing thread: the control path
        with warnings.catch_warnings():  # rospy warns about queue_size=None: here it is deliberate
            warnings.simplefilter("ignore", SyntaxWarning)
            return _Pub(rospy.Publisher(topic, msg_type, **kw))

    def subscribe(self, topic, msg_type, callback, qos=QoS.RELIABLE, depth=10, large=False):
        kw: dict = {"queue_size": depth, "tcp_nodelay": qos in (QoS.CONTROL, QoS.SENSOR, QoS.SYNCHRONOUS)}
        if large:
            kw["buff_size"] = 1 << 24
        return rospy.Subscriber(topic, msg_type, callback, **kw)

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

        return rospy.Subscriber(topic, rospy.AnyMsg, on_message, queue_size=1000, buff_size=2 ** 24,
                                tcp_nodelay=True), None

    def close(self, handle) -> None:
        if handle is None:
            return
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

        if self._tf_pub is None:
            with self._lock:
                if self._tf_pub is None:
                    self._tf_pub = rospy.Publisher("/tf", TFMessage, queue_size=100)
        self._tf_pub.publish(TFMessage(transforms=list(transforms)))

    def send_static_tf(self, transforms) -> None:
        from tf2_msgs.msg import TFMessage

        with self._lock:
            if self._static_pub is None:
                self._static_pub = rospy.Publisher("/tf_static", TFMessage, queue_size=100, latch=True)
            for t in transforms:
                self._static[t.child_frame_id] = t
            self._static_pub.publish(TFMessage(transforms=list(self._static.values())))

    def now(self):
        return rospy.Time.now()

    def params(self, defaults=None, describe=None, given=None) -> dict:
        p = rospy.get_param("~", {})
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
              namespace: str = "") -> Ros1Node:
    """``rospy.init_node`` (once per process) and the node's view."""
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
    return Ros1Node()


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


def flat_params(tree: dict) -> dict:
    """ROS 1 parameter names of a nested tree (``udp/port``)."""
    return flatten(tree, "/")
