"""The node interface on ROS 2 Jazzy (rclpy from the ``ros-jazzy-*`` PyPI wheels, ``.venv-ros2``).

Callbacks run on rclpy's ``EventsExecutor`` by default (``RAF_ROS2_EXECUTOR=events|single|multi``): one
thread, events handled as they come. The multi-threaded executor (closest to rospy's thread per
subscription) was measured to burn most of a core on the 100 Hz ``/clock`` a sim-time node hears
(ros2/rclpy#1223, #1378, #1452): the bridge's odom p99 was 242-500 ms beside it, 2.4-2.6 ms with the events
executor and 4.1 ms with the single-threaded one (docs/benchmarks.md). The bridge's control path runs in its
own thread, never in a callback; a service call is answered by a worker thread of its own (``Ros2Node.service``),
so a sim/* service that waits for the simulator does not hold up the node's other callbacks. Parameters are
declared (name ``udp.port``, the type of the default, a description, a range where one is known) before
they are read, so ``ros2 param list/describe`` shows every one. Discovery stays on this machine unless
``ROS_AUTOMATIC_DISCOVERY_RANGE`` says otherwise.
"""
from __future__ import annotations

import copy
import os
import sys
import threading
import time
from typing import Callable

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
# Fast DDS: a shared-memory segment that holds a camera image (the default 512 KB does not, so best-effort
# images went over UDP fragments and most were lost: data/fastdds.xml says more); a user's own profile wins
if not (os.environ.get("FASTRTPS_DEFAULT_PROFILES_FILE") or os.environ.get("FASTDDS_DEFAULT_PROFILES_FILE")):
    _profile = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "data",
                            "fastdds.xml")
    if os.path.isfile(_profile):
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = _profile

import rclpy  # noqa: E402
from builtin_interfaces.msg import Duration, Time  # noqa: E402
from rclpy.callback_groups import ReentrantCallbackGroup  # noqa: E402
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402

from ...errors import ConfigError  # noqa: E402
from .base import Node, Publisher, QoS, RawTopic, flatten, throttled, typed_like, typed_tree, unflatten  # noqa: E402

NAME = "ros2"


def time_msg(ns: int) -> Time:
    ns = int(ns)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def duration_msg(s: float) -> Duration:
    ns = int(round(s * 1e9))
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def diag_level(level: int) -> bytes:
    return bytes([int(level)])


def srv_types():
    """The package's service types: ``robotatfactory_msgs`` (built by scripts/bootstrap_ros2.sh from srv/*.srv)
    and std_srvs' Trigger."""
    import types

    import robotatfactory_msgs.srv as own
    from std_srvs.srv import Trigger

    ns = types.SimpleNamespace(**{k: getattr(own, k) for k in dir(own) if not k.startswith("_")})
    if not hasattr(ns, "Trigger"):
        ns.Trigger = Trigger
    return ns


def standard_sim_types():
    """ROS 2's simulation_interfaces (msg, srv, action modules; built by scripts/bootstrap_ros2.sh from
    ros2/simulation_interfaces, or the distribution's), or None when the package is not installed."""
    import types

    try:
        import simulation_interfaces.action as action
        import simulation_interfaces.msg as msg
        import simulation_interfaces.srv as srv
    except ImportError:
        return None
    return types.SimpleNamespace(msg=msg, srv=srv, action=action)


def serialize(msg) -> bytes:
    """A ROS 2 message object as it goes over the wire (CDR, little endian; what a rosbag2 holds)."""
    from rclpy.serialization import serialize_message

    return serialize_message(msg)


def require_master(hint: str) -> None:
    """ROS 2 has no master (nodes find each other by discovery): nothing to insist on."""
    return None


def qos_profile(qos: QoS, depth: int = 10) -> QoSProfile:
    depth = max(1, int(depth or 10))
    if qos is QoS.SENSOR:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.BEST_EFFORT,
                          durability=DurabilityPolicy.VOLATILE)
    if qos is QoS.LATCHED:  # (a late subscriber gets the last ``depth`` messages)
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
    if qos is QoS.CONTROL:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)


def subscriber_qos(qos: QoS, depth: int = 10) -> QoSProfile:
    """What a subscriber asks for: best effort for sensor data (it then matches reliable publishers too),
    transient local for latched topics, reliable otherwise."""
    return qos_profile(qos, depth)


def raw_subscription_qos(publishers) -> QoSProfile:
    """A QoS every one of ``publishers`` (``get_publishers_info_by_topic``) matches: reliable only if all are,
    transient local only if all are, keep last (at least 100 deep: a recorder must not drop a burst)."""
    profiles = [p.qos_profile for p in publishers]
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in profiles)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def message_class(msg_type: str):
    """``nav_msgs/msg/Odometry`` (or ``nav_msgs/Odometry``) -> the rclpy message class."""
    import importlib

    parts = msg_type.strip("/").split("/")
    pkg, kind, name = (parts[0], "msg", parts[1]) if len(parts) == 2 else parts
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


class _Pub(Publisher):
    def __init__(self, pub):
        self._pub = pub

    def publish(self, msg) -> None:
        self._pub.publish(msg)

    def subscriber_count(self) -> int:
        return self._pub.get_subscription_count()


class _Deferred:
    """A service request taken by the executor, to be answered by a worker thread (Ros2Node.service)."""

    __slots__ = ("request", "response")

    def __init__(self, request, response):
        self.request, self.response = request, response


class Ros2Node(Node):
    middleware = NAME

    def __init__(self, node: "rclpy.node.Node"):
        self.node = node
        self.group = ReentrantCallbackGroup()
        self._shutdown = threading.Event()
        self._lock = threading.Lock()
        self._tf_pub = None
        self._static_pub = None
        self._static: dict = {}
        self._keep: list = []
        self._workers: set = set()  # service calls being answered (service())
        self._clients: dict = {}  # (name, type) -> service client (call())
        self.executor = None  # made by spin() (make_executor) unless set before
        self._actions = None  # (companion node, its executor, its thread): action_server()
        self.callback_errors = 0  # callbacks that raised (logged, the node goes on)
        self.on_callback_error = None  # called with the error's text as well (tests: fail the test it happened in)

    @property
    def name(self) -> str:
        return self.node.get_fully_qualified_name()

    @property
    def namespace(self) -> str:
        return self.node.get_namespace()

    def resolve(self, name: str) -> str:
        return self.node.resolve_topic_name(name)

    def publisher(self, topic, msg_type, qos=QoS.RELIABLE, depth=10) -> Publisher:
        return _Pub(self.node.create_publisher(msg_type, topic, qos_profile(qos, depth)))

    def subscribe(self, topic, msg_type, callback, qos=QoS.RELIABLE, depth=10, large=False):
        sub = self.node.create_subscription(msg_type, topic, callback, subscriber_qos(qos, depth),
                                           callback_group=self.group)
        self._keep.append(sub)
        return sub

    def call(self, name, srv_type, /, timeout=5.0, **fields):
        with self._lock:
            key = (name, srv_type)
            cli = self._clients.get(key)
            if cli is None:
                cli = self._clients[key] = self.node.create_client(srv_type, name, callback_group=self.group)
        if not cli.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f"the service {name} is not offered within {timeout} s")
        fut = cli.call_async(srv_type.Request(**fields))
        done = threading.Event()
        fut.add_done_callback(lambda _f: done.set())
        if not done.wait(timeout):
            cli.remove_pending_request(fut)
            raise TimeoutError(f"{name}: no response within {timeout} s")
        return fut.result()

    def service(self, name, srv_type, handler):
        """Serve ``name``; each call runs ``handler`` in a worker thread of its own, which sends the answer
        (as rospy serves each call in a thread): a handler that waits (a ``sim/*`` service waiting up to 3 s
        for the simulator) does not hold up the node's other callbacks on the one-threaded executor.

        How: the executor calls the service's callback, then ``service.send_response(result, header)``
        (rclpy's executors and the EventsExecutor alike look the method up on the service object). The
        callback returns a :class:`_Deferred` request, and this service's ``send_response`` starts the
        worker for it with the header; the worker sends the handler's response with rclpy's own
        ``send_response``."""
        srv = self.node.create_service(srv_type, name, _Deferred, callback_group=self.group)
        send = srv.send_response  # rclpy's (bound): the worker answers with it

        def work(d: "_Deferred", header) -> None:
            try:
                try:
                    resp = handler(d.request, d.response)
                except Exception as e:  # noqa: BLE001 - as a callback's error: logged, the node goes on (no answer)
                    self._callback_failed(f"service {srv.srv_name} failed", e)
                    return
                try:
                    send(resp, header)
                except Exception as e:  # noqa: BLE001 - the service was closed meanwhile, or a wrong response type
                    if type(e).__name__ != "InvalidHandle":
                        self._callback_failed(f"service {srv.srv_name}: answer failed", e)
            finally:
                with self._lock:
                    self._workers.discard(threading.current_thread())

        def send_response(result, header) -> None:
            if not isinstance(result, _Deferred):
                send(result, header)
                return
            th = threading.Thread(target=work, args=(result, header), name=f"raf-srv{srv.srv_name}", daemon=True)
            with self._lock:
                self._workers.add(th)
            th.start()

        srv.send_response = send_response
        self._keep.append(srv)
        return srv

    def action_server(self, name, action_type, execute):
        """Actions are served by a companion rclpy node, ``<name>_actions`` in the same namespace, on a
        multi-threaded executor of its own: rclpy's EventsExecutor (the nodes' default) does not run action
        servers in Jazzy, and a goal that runs for long must not hold up cancel requests."""
        from rclpy.action import ActionServer, CancelResponse

        with self._lock:
            if self._actions is None:
                n = rclpy.create_node(f"{self.node.get_name()}_actions", namespace=self.node.get_namespace(),
                                      context=self.node.context)
                ex = MultiThreadedExecutor(num_threads=3, context=self.node.context)
                ex.add_node(n)
                th = threading.Thread(target=self._spin_loop, args=(ex,), name="raf-actions", daemon=True)
                self._actions = (n, ex, th)
                th.start()
            n = self._actions[0]
        ends = {"succeeded": "succeed", "aborted": "abort", "canceled": "canceled"}

        def run(goal_handle):
            try:
                outcome, result = execute(goal_handle.request, goal_handle.publish_feedback,
                                          lambda: goal_handle.is_cancel_requested)
            except Exception as e:  # noqa: BLE001 - as a callback's error: logged, the goal aborted
                self._callback_failed(f"action {name} failed", e)
                goal_handle.abort()
                return action_type.Result()
            getattr(goal_handle, ends[outcome])()
            return result

        srv = ActionServer(n, action_type, name, run, cancel_callback=lambda _g: CancelResponse.ACCEPT,
                           callback_group=ReentrantCallbackGroup())
        self._keep.append(srv)
        return srv

    def _callback_failed(self, what: str, e: Exception) -> None:
        """A callback or a service worker raised: counted (under the lock: workers are threads), logged, and
        handed to ``on_callback_error`` when set."""
        with self._lock:
            self.callback_errors += 1
        throttled(self.node.get_logger().error, 5.0, f"{what}: {e!r}")
        if self.on_callback_error is not None:
            self.on_callback_error(f"{what}: {e!r}")

    def timer(self, period, callback):
        t = self.node.create_timer(period, callback, callback_group=self.group)
        self._keep.append(t)
        return t

    def topic_types(self) -> dict[str, str]:
        return {topic: types[0] for topic, types in self.node.get_topic_names_and_types() if types}

    def subscribe_raw(self, topic, msg_type, callback):
        pubs = self.node.get_publishers_info_by_topic(topic)
        if not pubs:
            return None
        qos = raw_subscription_qos(pubs)
        info = RawTopic(type=msg_type, offered_qos=[p.qos_profile for p in pubs],
                        qos=f"{qos.reliability.name.lower()}, {qos.durability.name.lower()}")
        sub = self.node.create_subscription(message_class(msg_type), topic, lambda data: callback(data, info), qos,
                                            raw=True, callback_group=self.group)
        return sub, info

    def close(self, handle) -> None:
        if handle is None:
            return
        from rclpy.client import Client
        from rclpy.publisher import Publisher as RclPublisher
        from rclpy.service import Service
        from rclpy.subscription import Subscription
        from rclpy.timer import Timer

        inner = handle._pub if isinstance(handle, _Pub) else handle
        n = self.node
        if isinstance(inner, Subscription):
            destroy = n.destroy_subscription
        elif isinstance(inner, RclPublisher):
            destroy = n.destroy_publisher
        elif isinstance(inner, Service):
            destroy = n.destroy_service
        elif isinstance(inner, Timer):
            destroy = n.destroy_timer
        elif isinstance(inner, Client):
            destroy = n.destroy_client
        elif type(inner).__name__ == "ActionServer":  # rclpy.action's, made by action_server()
            destroy = _destroy_action_server
        else:
            raise TypeError(f"close: not a subscription, publisher, service or timer: {handle!r}")
        with self._lock:
            if inner in self._keep:
                self._keep.remove(inner)
        try:
            if isinstance(inner, Timer):
                inner.cancel()
            destroy(inner)  # False when it is gone already (closed before, or with the node)
        except Exception:  # noqa: BLE001 - InvalidHandle: destroyed with the node
            pass

    def send_tf(self, transforms) -> None:
        from tf2_msgs.msg import TFMessage

        if self._tf_pub is None:
            with self._lock:
                if self._tf_pub is None:  # tf2_ros's TransformBroadcaster's QoS: reliable, keep last 100
                    self._tf_pub = self.node.create_publisher(TFMessage, "/tf", qos_profile(QoS.RELIABLE, 100))
        self._tf_pub.publish(TFMessage(transforms=list(transforms)))

    def send_static_tf(self, transforms) -> None:
        from tf2_msgs.msg import TFMessage

        with self._lock:
            if self._static_pub is None:  # tf2_ros's StaticTransformBroadcaster: transient local, keep last 1
                self._static_pub = self.node.create_publisher(TFMessage, "/tf_static", qos_profile(QoS.LATCHED))
            for t in transforms:
                self._static[t.child_frame_id] = t
            self._static_pub.publish(TFMessage(transforms=list(self._static.values())))

    def now(self):
        return self.node.get_clock().now().to_msg()

    def params(self, defaults=None, describe=None, given=None) -> dict:
        """Declare every leaf of ``defaults`` (``udp.port``; with ``given`` merged over them) and return the
        values as a nested dict; a parameter given to the node that no default names is an error (as the
        ROS 1 nodes' ``~`` check). ROS 2 types parameters strictly: a whole number given where the default
        is a real (in ``given``, an override, a parameter file) is made a real here (base.typed_like), the
        one place of that rule."""
        from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
        from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
        from rclpy.parameter import Parameter

        if given:
            from ...settings import deep_update

            defaults = copy.deepcopy(defaults or {})
            deep_update(defaults, typed_tree(given, defaults))
        flat = flatten(defaults or {}, ".")
        overrides = getattr(self.node, "_parameter_overrides", {})
        for key, value in flat.items():
            if self.node.has_parameter(key):
                continue
            o = overrides.get(key)
            if o is not None and o.type_ in (Parameter.Type.INTEGER, Parameter.Type.INTEGER_ARRAY):
                v = o.value if o.type_ == Parameter.Type.INTEGER else list(o.value)
                typed = typed_like(v, value)
                if repr(typed) != repr(v):  # 3 -> 3.0, [1, 2] -> [1.0, 2.0]
                    overrides[key] = Parameter(key, value=typed)
            text, rng = describe(key) if describe else ("", None)
            d = ParameterDescriptor(name=key, description=text or "")
            if isinstance(value, (list, tuple)):
                value = _homogeneous(list(value))
                if not value:
                    d.dynamic_typing = True
                    value = None
            elif isinstance(value, float) and rng is not None:
                d.floating_point_range = [FloatingPointRange(from_value=float(rng[0]), to_value=float(rng[1]))]
            elif isinstance(value, int) and not isinstance(value, bool) and rng is not None:
                d.integer_range = [IntegerRange(from_value=int(rng[0]), to_value=int(rng[1]), step=0)]
            if value is None:
                d.dynamic_typing = True
            try:
                self.node.declare_parameter(key, value, d)
            except InvalidParameterTypeException as e:
                want = type(value).__name__
                raise ConfigError(f"parameter {key}: {e} (the default {value!r} is a {want})") from None
            except InvalidParameterValueException as e:
                raise ConfigError(f"parameter {key}: {e}") from None
        unknown = sorted(k for k in getattr(self.node, "_parameter_overrides", {})
                         if k not in flat and k != "use_sim_time" and not k.startswith("qos_overrides."))
        if unknown and defaults:
            raise ConfigError(f"unknown parameter(s) {', '.join(unknown)}; known: see the node's YAML file")
        out = {}
        for key in flat:
            p = self.node.get_parameter(key)
            v = p.value
            if p.type_ == Parameter.Type.NOT_SET:
                v = flat[key]
            out[key] = list(v) if isinstance(v, (list, tuple)) or type(v).__name__ == "array" else v
        return unflatten(out, ".")

    def log(self, level, text, throttle=0.0) -> None:
        fns = self.__dict__.get("_log_fns")
        if fns is None:  # one function per level, made once (the throttling keys on it)
            import functools

            lg = self.node.get_logger()
            fns = self._log_fns = {lv: functools.partial(_emit, lg, lv)
                                   for lv in ("debug", "info", "warn", "error", "fatal")}
        fn = fns[level]
        if throttle > 0:
            throttled(fn, throttle, text)
        else:
            fn(text)

    def ok(self) -> bool:
        return not self._shutdown.is_set() and rclpy.ok(context=self.node.context)

    def shutdown(self, reason: str = "") -> None:
        if reason:
            self.node.get_logger().info(f"shutting down: {reason}")
        self._shutdown.set()

    def set_executor(self, kind: str) -> None:
        self.executor = make_executor(self.node.context, kind)

    def spin_in_background(self, name: str) -> threading.Thread:
        th = threading.Thread(target=self.spin, name=name, daemon=True)
        th.start()
        return th

    def finish(self, reason: str = "", spinner: threading.Thread | None = None) -> None:
        self.shutdown(reason)
        if spinner is not None:
            spinner.join(5.0)
        self.destroy()
        rclpy.try_shutdown()

    def spin(self) -> None:
        ex = self.executor or make_executor(self.node.context)
        self.executor = ex
        ex.add_node(self.node)
        try:
            self._spin_loop(ex)
        finally:
            self._shutdown.set()

    def _spin_loop(self, ex) -> None:
        """Spin ``ex`` until the node shuts down (the node's executor, or the action servers' own)."""
        while self.ok():
            try:
                ex.spin_once(timeout_sec=0.1)
            except (KeyboardInterrupt, ExternalShutdownException):
                return
            except Exception as e:  # noqa: BLE001 - a callback's error must not end the node (as in rospy)
                if type(e).__name__ == "InvalidHandle":  # an entity destroyed while the executor held it
                    continue
                self._callback_failed("a callback failed (node goes on)", e)

    def destroy(self) -> None:
        self._shutdown.set()
        with self._lock:
            workers = list(self._workers)
        end = time.monotonic() + 3.5  # service calls being answered (a sim/* call waits up to 3 s)
        for th in workers:
            th.join(max(0.0, end - time.monotonic()))
        if self._actions is not None:
            n, ex, th = self._actions
            th.join(1.0)
            try:
                ex.shutdown(timeout_sec=1.0)
                n.destroy_node()
            except Exception:  # noqa: BLE001 - already torn down
                pass
        try:
            if self.executor is not None:
                self.executor.shutdown(timeout_sec=1.0)
            self.node.destroy_node()
        except Exception:  # noqa: BLE001 - already torn down
            pass


def _destroy_action_server(server) -> bool:
    server.destroy()
    return True


def _emit(lg, level: str, text: str) -> None:
    """One calling line per severity: rclpy keys a logger's context by the line that calls it and raises
    "Logger severity cannot be changed between calls" when one line logs at two severities."""
    if level == "debug":
        lg.debug(text)
    elif level == "info":
        lg.info(text)
    elif level == "warn":
        lg.warning(text)
    elif level == "error":
        lg.error(text)
    else:
        lg.fatal(text)


EXECUTORS = ("events", "single", "multi")


def make_executor(context, kind: str | None = None):
    """The executor a node spins on: ``kind`` or ``RAF_ROS2_EXECUTOR`` (default ``events``)."""
    kind = (kind or os.environ.get("RAF_ROS2_EXECUTOR", "events")).strip().lower()
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor(context=context)
    if kind == "single":
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    if kind == "multi":
        return MultiThreadedExecutor(num_threads=4, context=context)
    raise ConfigError(f"RAF_ROS2_EXECUTOR={kind!r}: use one of {', '.join(EXECUTORS)}")


def _homogeneous(values: list) -> list:
    """ROS 2 arrays hold one type: ints among floats become floats."""
    if any(isinstance(v, float) for v in values) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                         for v in values):
        return [float(v) for v in values]
    return values


# ---- the process's node ---------------------------------------------------------------------------------

def init_node(name: str, argv: list[str] | None = None, anonymous: bool = False, signals: bool = True,
              namespace: str = "", params: dict | None = None, sim_time: bool | None = None) -> Ros2Node:
    """``rclpy.init`` (once per process) and a node. ``params``: overrides, nested or flat (``a/b`` or
    ``a.b`` keys); ``sim_time``: set ``use_sim_time``."""
    from rclpy.node import Node as RclNode
    from rclpy.parameter import Parameter

    if not rclpy.ok():
        from rclpy.signals import SignalHandlerOptions

        rclpy.init(args=argv if argv is not None else sys.argv,
                   signal_handler_options=None if signals else SignalHandlerOptions.NO)
    if anonymous:
        import uuid

        name = f"{name}_{uuid.uuid4().hex[:8]}"
    overrides = []
    for key, value in flatten(params or {}, ".").items():
        key = key.replace("/", ".")
        if isinstance(value, (list, tuple)):
            value = _homogeneous(list(value))
        overrides.append(Parameter(key, value=value))
    if sim_time is not None:
        overrides.append(Parameter("use_sim_time", value=bool(sim_time)))
    n = RclNode(name, namespace=("/" + namespace.strip("/")) if namespace.strip("/") else None,
                parameter_overrides=overrides or None)
    return Ros2Node(n)


def myargv(argv: list[str]) -> list[str]:
    """The command line without ROS 2's ``--ros-args ...`` part."""
    from rclpy.utilities import remove_ros_args

    return remove_ros_args(argv)


def run_node(args, who: str, params: dict, make_node: Callable[[Node], object],
             started: Callable[[object], str]) -> int:
    """Run one node from the command line until Ctrl-C: the node gets ``params`` as parameter overrides (so
    ``ros2 param get`` shows them) and ``use_sim_time`` unless ``--no-sim-time``."""
    if getattr(args, "roscore", False):
        print(f"raf {who}: --roscore: ROS 2 has no master (discovery is peer to peer; ROS_DOMAIN_ID="
              f"{os.environ.get('ROS_DOMAIN_ID', '0')}, range {os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE']})",
              flush=True)
    tree = params.get("", None) if "" in params else unflatten({k.replace("/", "."): v for k, v in params.items()}, ".")
    node = init_node(args.name, argv=[sys.argv[0]], namespace=args.ns, params=tree,
                     sim_time=not args.no_sim_time)
    obj = None
    try:
        obj = make_node(node)
        print(f"raf {who}: {started(obj)}", flush=True)
        node.spin()
    finally:
        if obj is not None:
            obj.stop()
        node.finish()
    return 0


def spin_node(name: str, make_node: Callable[[Node], object], argv: list[str] | None = None) -> int:
    """A node's ``main`` under ``ros2 launch`` / ``ros2 run``: init (parameters from ``--ros-args``), build,
    spin, stop. A bad parameter is logged as fatal and ends the node with exit code 2."""
    node = init_node(name, argv=argv if argv is not None else sys.argv)
    try:
        obj = make_node(node)
    except ConfigError as e:
        node.fatal(f"{name}: {e}")
        node.finish()
        return 2
    try:
        node.spin()
    finally:
        obj.stop()
        node.finish()
    return 0


def flat_params(tree: dict) -> dict:
    """ROS 2 parameter names of a nested tree (``udp.port``)."""
    return flatten(tree, ".")
