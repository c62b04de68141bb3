"""ROS helpers for tests, on this interpreter's middleware (``.venv``: ROS 1, ``.venv-ros2``: ROS 2).

A private graph for the whole pytest process: ROS 1's roscore on a free port (never 11311), or ROS 2's
domain id of its own (:class:`robotatfactory.ros.master.PrivateDomain`, its environment applied to this
process before rclpy is initialised). rospy allows ``init_node`` once per process and binds it to the master
it was given, and one rclpy context per test process keeps things simple: use the session fixture
``ros_graph`` (alias ``ros_master``; import it into a test module: ``from rosutil import ros_graph  # noqa:
F401``) and ``test_node()``, the middleware's :class:`~robotatfactory.ros.mw.base.Node` of this process
(ROS 2: spun by an executor in a background thread, destroyed at exit). Child processes (``raf bridge``,
``roslaunch``, ...) get ``ros_graph.env()`` (which names the middleware in ``RAF_MIDDLEWARE``).

    def test_x(ros_graph):
        node = test_node()
        odom = Collector("/odom", Odometry)     # QoS by topic: see QOS_OF
        odom.wait(5, timeout=10)
        r = call_service("/sim/get_state", srv_types().GetSimulationState)
"""
from __future__ import annotations

import atexit
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
from robotatfactory.ros import mw  # noqa: E402
from robotatfactory.ros.master import PrivateDomain, PrivateMaster, free_port, stop_process  # noqa: E402,F401
from robotatfactory.ros.mw import QoS  # noqa: E402
from robotatfactory.ros.mw.base import level_int, stamp_ns, stamp_s  # noqa: E402,F401


class RosMaster(PrivateMaster):
    """``roscore -p PORT`` on a free port (see :class:`robotatfactory.ros.master.PrivateMaster`)."""


_GRAPH: "RosMaster | PrivateDomain | None" = None
_NODE_LOCK = threading.Lock()
_NODE = None
_SPIN: threading.Thread | None = None


def middleware() -> str:
    """This process's middleware (``ros1`` / ``ros2``)."""
    return mw.name()


def graph() -> "RosMaster | PrivateDomain":
    """The process-wide private graph (started on first use, stopped at exit)."""
    global _GRAPH
    if _GRAPH is None:
        g = PrivateDomain().start() if middleware() == "ros2" else RosMaster().start()
        g.use_in_this_process()
        os.environ["RAF_MIDDLEWARE"] = middleware()
        _GRAPH = g
        atexit.register(g.cleanup)
    return _GRAPH


master = graph  # the ROS 1 name


@pytest.fixture(scope="session")
def ros_graph():
    yield graph()


ros_master = ros_graph  # the ROS 1 name, kept for the tests that use it


def test_node(name: str = "raf_test"):
    """The middleware node of this process against :func:`graph` (made once). ROS 1: ``rospy.init_node``;
    ROS 2: ``rclpy.init`` and a node spun by the nodes' executor (mw.ros2.make_executor) in a background
    thread, destroyed (and rclpy shut down) at exit."""
    global _NODE, _SPIN
    graph()
    with _NODE_LOCK:
        if _NODE is None:
            api = mw.api()
            if middleware() == "ros2":
                node = api.init_node(name, argv=[sys.argv[0]], anonymous=True, signals=False)
                node.on_callback_error = SPIN_ERRORS.append  # a service worker's error fails its test too
                _SPIN = threading.Thread(target=_spin_ros2, args=(node,), name="raf-test-spin", daemon=True)
                _SPIN.start()
                atexit.register(_destroy_ros2_node, node)
            else:
                import rospy

                api.loopback_ros_default()
                rospy.init_node(name, anonymous=True, disable_signals=True)
                node = api.Ros1Node()
            _NODE = node
    return _NODE


test_node.__test__ = False  # not a pytest test


SPIN_ERRORS: list[str] = []  # what the ROS 2 spin thread caught, except the destruction race (see _spin_ros2)
RACES = [0]  # how many rounds the destruction race cost


def _spin_ros2(node) -> None:
    """Spin the test node until it shuts down; the spin thread must outlive every test of the process. rclpy
    raises InvalidHandle out of ``spin_once`` when a test destroys a subscription or publisher while the
    executor collects it: counted in RACES, spinning goes on. Any other error (a callback of a node under
    test raised) goes into SPIN_ERRORS, which conftest turns into a failure of the test it happened in."""
    from rclpy.executors import ExternalShutdownException

    from robotatfactory.ros.mw.ros2 import make_executor

    # the nodes' own executor (events by default): a multi-threaded one in this process burned enough of the
    # interpreter to starve the FakeSim threads beside it under load (14 datagrams a second instead of 25)
    ex = make_executor(node.node.context)
    node.executor = ex
    ex.add_node(node.node)
    while node.ok():
        try:
            ex.spin_once(timeout_sec=0.1)
        except ExternalShutdownException:
            break
        except Exception as e:  # noqa: BLE001 - see the docstring
            if type(e).__name__ == "InvalidHandle":
                RACES[0] += 1
                continue
            import traceback

            SPIN_ERRORS.append("".join(traceback.format_exception(e))[-3000:])


def _destroy_ros2_node(node) -> None:
    """Stop the spin thread, destroy the node, shut rclpy down: a daemon thread still in rclpy at interpreter
    exit aborts Python."""
    import rclpy

    node.shutdown()
    if _SPIN is not None:
        _SPIN.join(5)
    node.destroy()
    rclpy.try_shutdown()


def srv_types():
    """The package's service types on this middleware (ROS 1: generated classes; ROS 2: robotatfactory_msgs)."""
    return mw.api().srv_types()


def raf_process(args: list[str], env: dict, log: Path | None = None) -> subprocess.Popen:
    """``raf ARGS`` with this interpreter, in its own process group, output to ``log`` (or discarded)."""
    out = open(log, "wb") if log else subprocess.DEVNULL
    return subprocess.Popen([sys.executable, "-m", "robotatfactory", *args], env=env, stdout=out,
                            stderr=subprocess.STDOUT, start_new_session=True, cwd=str(ROOT))


# QoS a test subscriber asks for, by topic (the last part of the name): ROS 2 needs a best-effort subscriber
# for the sensor topics and a transient-local one to get latched messages; ROS 1 ignores it
# (a transient-local subscriber does not match a volatile publisher: only the topics that are latched)
QOS_OF = {"scan": QoS.SENSOR, "camera/image_raw": QoS.SENSOR, "camera/camera_info": QoS.SENSOR,
          "tf_static": QoS.LATCHED, "field/markers": QoS.LATCHED}


def qos_of(topic: str) -> QoS:
    """The QoS a test subscriber of ``topic`` asks for (by the end of its name: ``/robot1/scan`` is a scan)."""
    t = "/" + topic.strip("/")
    return next((q for k, q in QOS_OF.items() if t.endswith("/" + k)), QoS.RELIABLE)


class Collector:
    """Subscribes to a topic and keeps every message with its receive time (monotonic)."""

    def __init__(self, topic: str, msg_type, maxlen: int = 100000, qos: QoS | None = None, depth: int = 100):
        self.node = test_node()
        self.topic = topic
        self.msgs: list = []
        self.times: list[float] = []
        self.maxlen = maxlen
        self._lock = threading.Lock()
        q = qos if qos is not None else qos_of(topic)
        self.sub = self.node.subscribe(topic, msg_type, self._cb, q, depth=depth,
                                       large=msg_type.__name__ == "Image")

    def _cb(self, m):
        with self._lock:
            if len(self.msgs) < self.maxlen:
                self.msgs.append(m)
                self.times.append(time.monotonic())

    def wait(self, n: int = 1, timeout: float = 10.0, pred=None) -> list:
        end = time.monotonic() + timeout
        got: list = []
        while time.monotonic() < end:
            with self._lock:
                got = [m for m in self.msgs if pred is None or pred(m)]
            if len(got) >= n:
                return got
            time.sleep(0.02)
        raise TimeoutError(f"{self.topic}: {len(got)} of {n} messages within {timeout} s")

    def clear(self):
        with self._lock:
            self.msgs.clear()
            self.times.clear()

    def publishers(self) -> int:
        """How many publishers this subscription is connected to (ROS 1) / the topic has (ROS 2)."""
        if middleware() == "ros2":
            return self.node.node.count_publishers(self.node.resolve(self.topic))
        return self.sub.get_num_connections()

    def close(self):
        unsubscribe(self.sub)


def unsubscribe(sub) -> None:
    """End a subscription made with ``test_node().subscribe``."""
    test_node().close(sub)


def publisher(topic: str, msg_type, qos: QoS = QoS.CONTROL, depth: int = 1, wait_for: float = 10.0):
    """A publisher of the test node; with ``wait_for`` > 0, returned once a subscriber is connected."""
    pub = test_node().publisher(topic, msg_type, qos, depth)
    if wait_for > 0:
        wait_until(lambda: pub.subscriber_count() > 0, wait_for, what=f"a subscriber to {topic}")
    return pub


def unpublish(pub) -> None:
    """End a publisher made with :func:`publisher` / ``test_node().publisher``."""
    test_node().close(pub)


def wait_for_service(name: str, srv_type=None, timeout: float = 30.0) -> None:
    if middleware() == "ros2":
        wait_until(lambda: name in service_names(), timeout, what=f"the service {name}")
    else:
        import rospy

        rospy.wait_for_service(name, timeout=timeout)


def service_names() -> set[str]:
    if middleware() == "ros2":
        return {n for n, _ in test_node().node.get_service_names_and_types()}
    import rosservice

    return set(rosservice.get_service_list())


def call_service(name: str, srv_type, /, timeout: float = 30.0, **fields):
    """Call a service with the request's fields as keywords; the response (the test node's ``call``: ROS 1
    rospy's ServiceProxy; ROS 2 a client's call_async, waited for while the test node spins in its thread)."""
    return test_node().call(name, srv_type, timeout, **fields)


def node_names() -> list[str]:
    """Fully qualified names of the nodes in the graph."""
    if middleware() == "ros2":
        return [(ns.rstrip("/") + "/" + n) for n, ns in test_node().node.get_node_names_and_namespaces()]
    import rosnode

    return list(rosnode.get_node_names())


def wait_for_node(suffix: str, timeout: float = 30.0) -> None:
    """Until a node whose fully qualified name ends in ``suffix`` is in the graph."""
    test_node()
    wait_until(lambda: any(n.endswith(suffix) for n in node_names()), timeout, what=f"the node {suffix}")


def publisher_qos(topic: str) -> list:
    """ROS 2: the QoS profiles the publishers of ``topic`` offer (rclpy's QoSProfile)."""
    return [i.qos_profile for i in test_node().node.get_publishers_info_by_topic(topic)]


def subscription_qos(topic: str) -> list:
    """ROS 2: the QoS profiles the subscriptions of ``topic`` ask for."""
    return [i.qos_profile for i in test_node().node.get_subscriptions_info_by_topic(topic)]


def node_parameters(node_name: str, names: list[str] | None = None, timeout: float = 10.0) -> dict:
    """ROS 2: ``{name: (value, description)}`` of a node's declared parameters, through its parameter
    services (list_parameters, get_parameters, describe_parameters), as ``ros2 param`` reads them."""
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
    from rclpy.parameter import parameter_value_to_python

    if names is None:
        names = list(call_service(f"{node_name}/list_parameters", ListParameters, timeout).result.names)
    vals = call_service(f"{node_name}/get_parameters", GetParameters, timeout, names=names).values
    desc = call_service(f"{node_name}/describe_parameters", DescribeParameters, timeout, names=names).descriptors
    return {n: (parameter_value_to_python(v), d) for n, v, d in zip(names, vals, desc)}


def wait_until(pred, timeout: float = 10.0, interval: float = 0.02, what: str = "condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    raise TimeoutError(f"{what} not met within {timeout} s")


# ---- TF: a small buffer of the latest transforms, on either middleware ---------------------------------------

def _matrix(t) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    q, p = t.transform.rotation, t.transform.translation
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    T[:3, 3] = (p.x, p.y, p.z)
    return T


class TFTree:
    """The latest transform of every child frame from ``/tf`` and ``/tf_static`` (ROS 2 has no tf2_ros wheel,
    so lookups compose the chain here; the same code on ROS 1). ``lookup(target, source)`` is the 4x4
    target <- source; ``try_lookup`` also gives the chain's latest common time (the oldest of its dynamic
    links' latest stamps, what tf2 resolves ``Time(0)`` to)."""

    def __init__(self):
        from tf2_msgs.msg import TFMessage

        self._lock = threading.Lock()
        self.parent: dict[str, str] = {}
        self.tf: dict[str, object] = {}
        self.static_children: set[str] = set()
        node = test_node()
        self.subs = [node.subscribe("/tf", TFMessage, lambda m: self._on(m, False), QoS.RELIABLE, depth=100),
                     node.subscribe("/tf_static", TFMessage, lambda m: self._on(m, True), QoS.LATCHED, depth=100)]

    def _on(self, msg, static: bool) -> None:
        with self._lock:
            for t in msg.transforms:
                self.parent[t.child_frame_id] = t.header.frame_id
                self.tf[t.child_frame_id] = t
                if static:
                    self.static_children.add(t.child_frame_id)

    def _chain(self, frame: str) -> list[str]:
        out = [frame]
        while out[-1] in self.parent and len(out) < 100:
            out.append(self.parent[out[-1]])
        return out

    def try_lookup(self, target: str, source: str):
        """(T target<-source, stamp_s of the chain's newest dynamic transform or None) or None."""
        with self._lock:
            a, b = self._chain(target), self._chain(source)
            common = next((f for f in a if f in b), None)
            if common is None:
                return None

            def up(chain):
                T, stamp = np.eye(4), None
                for f in chain[:chain.index(common)]:
                    t = self.tf[f]
                    T = _matrix(t) @ T
                    if f not in self.static_children:
                        s = stamp_s(t.header.stamp)
                        stamp = s if stamp is None else min(stamp, s)
                return T, stamp

            Ta, sa = up(a)  # common <- target
            Tb, sb = up(b)  # common <- source
            stamps = [s for s in (sa, sb) if s is not None]
            return np.linalg.inv(Ta) @ Tb, (min(stamps) if stamps else None)

    def lookup(self, target: str, source: str, timeout: float = 10.0) -> np.ndarray:
        return wait_until(lambda: self.try_lookup(target, source), timeout,
                          what=f"the transform {target} <- {source}")[0]

    def can_transform(self, target: str, source: str, timeout: float = 10.0) -> bool:
        try:
            self.lookup(target, source, timeout)
            return True
        except TimeoutError:
            return False

    def close(self) -> None:
        for s in self.subs:
            unsubscribe(s)
