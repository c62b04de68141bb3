"""``raf record``'s node: subscribes to topics as they appear on the graph and writes every message, as it came
off the wire (no deserialization), into a bag (:mod:`.bags`): a rosbag2 on ROS 2, a ROS 1 bag on ROS 1.

The one part that differs per middleware is how a topic is found and subscribed to without knowing its
type in advance: ROS 1 lists published topics on the master and subscribes with ``rospy.AnyMsg`` (the
connection header carries the type, MD5 and definition, written to the bag as they are); ROS 2 lists
topics and their publishers' QoS on the graph and subscribes with ``raw=True`` with the QoS that matches
every publisher (``ros2 bag record``'s rule: reliable when all publishers are, transient local when all
are, e.g. ``/tf_static`` and the field's markers), and the bag records the offered QoS so that
``ros2 bag play`` republishes latched topics as latched.

Bag time is the node's clock at reception: simulation time under ``use_sim_time`` (the default, as the
bridge publishes ``/clock``), 0 for what arrives before the first ``/clock`` (the latched topics); or the
wall clock (``wall_time``).
"""
from __future__ import annotations

import threading
import time

from .bags import BagWriter, normalize_type
from .mw.base import Node, stamp_ns

#: What ``raf record`` records by default (relative names resolve in the node's namespace). The camera
#: image is the bulk: ``--no-images`` leaves it out.
DEFAULT_TOPICS = ("/clock", "/tf", "/tf_static", "odom", "ground_truth", "scan", "camera/image_raw",
                  "camera/camera_info", "joint_states", "cmd_vel", "electromagnet", "electromagnet/state",
                  "contact", "field/markers", "pose", "camera_pose", "/diagnostics")
IMAGE_TOPICS = ("camera/image_raw", "aruco/debug_image")


class Recorder:
    """Records ``topics`` (resolved names) from ``node`` into ``writer`` until :meth:`stop`."""

    def __init__(self, node: Node, writer: BagWriter, topics: list[str], rescan: float = 0.5,
                 wall_time: bool = False):
        """``wall_time``: bag time from the wall clock instead of the node's (ROS) clock."""
        self.node = node
        self.wall_time = wall_time
        self.writer = writer
        self.topics = [node.resolve(t) for t in topics]
        self.rescan = rescan
        self.errors = 0
        self._subs: dict[str, object] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    # -- life ---------------------------------------------------------------------------------------------
    def start(self) -> "Recorder":
        self._scan()
        self._thread = threading.Thread(target=self._scan_loop, name="raf-record-scan", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        for s in list(self._subs.values()):
            self.node.close(s)
        self.writer.close()

    def subscribed(self) -> list[str]:
        return sorted(self._subs)

    def _scan_loop(self) -> None:
        while not self._stop.wait(self.rescan):
            try:
                self._scan()
            except Exception as e:  # noqa: BLE001 - a graph query that failed once: try again next round
                self.errors += 1
                self.node.warn(f"record: listing the graph's topics failed: {e}", throttle=10.0)

    def _stamp(self) -> int:
        return time.time_ns() if self.wall_time else stamp_ns(self.node.now())

    # -- per middleware -------------------------------------------------------------------------------
    def _scan(self) -> None:
        if self.node.middleware == "ros2":
            self._scan_ros2()
        else:
            self._scan_ros1()

    def _scan_ros1(self) -> None:
        import rospy

        published = dict(rospy.get_published_topics())
        for topic in self.topics:
            if topic in self._subs or topic not in published:
                continue
            self._subs[topic] = rospy.Subscriber(topic, rospy.AnyMsg, self._on_ros1, callback_args=topic,
                                                 queue_size=1000, buff_size=2 ** 24, tcp_nodelay=True)
            self.node.info(f"record: {topic} ({published[topic]})")

    def _on_ros1(self, msg, topic: str) -> None:
        if self._stop.is_set():
            return
        try:
            data = getattr(msg, "_buff", None)
            if data is None:  # rospy shares one subscription per topic: on /clock its own typed one
                import io

                buf = io.BytesIO()
                msg.serialize(buf)
                data = buf.getvalue()
                header = {"type": msg._type, "md5sum": msg._md5sum, "message_definition": msg._full_text}
            else:
                header = msg._connection_header
            if not self.writer.has_topic(topic):
                self.writer.add_topic(topic, header["type"], msgdef=header["message_definition"],
                                      digest=header["md5sum"], latched=header.get("latching") == "1")
            self.writer.write_raw(topic, data, self._stamp())
        except Exception as e:  # noqa: BLE001 - count, log, keep recording the rest
            self.errors += 1
            self.node.warn(f"record: {topic}: {e}", throttle=5.0)

    def _scan_ros2(self) -> None:
        rcl = self.node.node  # the rclpy node behind mw's Ros2Node
        types = dict(rcl.get_topic_names_and_types())
        for topic in self.topics:
            if topic in self._subs or topic not in types or not types[topic]:
                continue
            pubs = rcl.get_publishers_info_by_topic(topic)
            if not pubs:
                continue
            msgtype = types[topic][0]
            cls = _ros2_class(msgtype)
            qos = _ros2_subscription_qos(pubs)
            if not self.writer.has_topic(topic):
                self.writer.add_topic(topic, msgtype, qos=[_rosbags_qos(p.qos_profile) for p in pubs])
            self._subs[topic] = rcl.create_subscription(cls, topic, lambda data, t=topic: self._on_ros2(t, data),
                                                        qos, raw=True, callback_group=self.node.group)
            self.node.info(f"record: {topic} ({normalize_type(msgtype)}, {qos.reliability.name.lower()}, "
                           f"{qos.durability.name.lower()})")

    def _on_ros2(self, topic: str, data: bytes) -> None:
        if self._stop.is_set():
            return
        try:
            self.writer.write_raw(topic, data, self._stamp())
        except Exception as e:  # noqa: BLE001
            self.errors += 1
            self.node.warn(f"record: {topic}: {e}", throttle=5.0)


def _ros2_class(msgtype: str):
    """``nav_msgs/msg/Odometry`` -> the rclpy message class."""
    import importlib

    pkg, kind, name = normalize_type(msgtype).split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def _ros2_subscription_qos(publishers):
    """A QoS every publisher matches: reliable only if all are, transient local only if all are, keep last
    (at least 100 deep: a recorder must not drop a burst)."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    profiles = [p.qos_profile for p in publishers]
    reliable = all(q.reliability == ReliabilityPolicy.RELIABLE for q in profiles)
    latched = all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def _rosbags_qos(q):
    """An rclpy QoSProfile as rosbags' Qos (what metadata.yaml's offered_qos_profiles lists)."""
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    def dur(d) -> QosTime:
        ns = int(getattr(d, "nanoseconds", 0))
        return QosTime(ns // 1_000_000_000, ns % 1_000_000_000)

    return Qos(history=QosHistory(int(q.history)), depth=int(q.depth), reliability=QosReliability(int(q.reliability)),
               durability=QosDurability(int(q.durability)), deadline=dur(q.deadline), lifespan=dur(q.lifespan),
               liveliness=QosLiveliness(int(q.liveliness)), liveliness_lease_duration=dur(q.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(q.avoid_ros_namespace_conventions))


def wait_wall(seconds: float | None, ok) -> None:
    """Sleep until ``seconds`` of wall time passed (None: forever) or ``ok()`` turns false."""
    end = None if seconds is None else time.monotonic() + seconds
    while ok() and (end is None or time.monotonic() < end):
        time.sleep(0.05)
