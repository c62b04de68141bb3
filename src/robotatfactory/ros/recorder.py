"""``raf record``'s node: subscribes to topics as they appear on the graph and writes every message, as it came
off the wire (no deserialization), into a bag (:mod:`.bags`): a rosbag2 on ROS 2, a ROS 1 bag on ROS 1.

The one part that differs per middleware is how a topic is found and subscribed to without knowing its
type in advance (:meth:`~.mw.base.Node.topic_types`, :meth:`~.mw.base.Node.subscribe_raw`): ROS 1 lists
published topics on the master and subscribes with ``rospy.AnyMsg`` (the connection header carries the type,
MD5 and definition, written to the bag as they are); ROS 2 lists topics and their publishers' QoS on the
graph and subscribes with ``raw=True`` with the QoS that matches every publisher (``ros2 bag record``'s rule:
reliable when all publishers are, transient local when all are, e.g. ``/tf_static`` and the field's
markers), and the bag records the offered QoS so that ``ros2 bag play`` republishes latched topics as
latched.

Bag time is the node's clock at reception: simulation time under ``use_sim_time`` (the default, as the
bridge publishes ``/clock``), or the wall clock (``wall_time``). On simulation time the recording starts at
the node's first ``/clock`` (as ``rosbag record`` waits for a valid time): nothing is subscribed to before
it, so no message gets the invalid time 0, and the latched topics arrive once it has started.
"""
from __future__ import annotations

import threading
import time

from .bags import BagWriter
from .mw.base import Node, RawTopic, stamp_ns

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
        #: set once the clock is valid (at once on wall time): the recording has started
        self.recording = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._waiting_told = False

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
        while not self._stop.wait(self.rescan if self.recording.is_set() else min(self.rescan, 0.02)):
            try:
                self._scan()
            except Exception as e:  # noqa: BLE001 - a graph query that failed once: try again next round
                self.errors += 1
                self.node.warn(f"record: listing the graph's topics failed: {e}", throttle=10.0)

    def _stamp(self) -> int:
        return time.time_ns() if self.wall_time else stamp_ns(self.node.now())

    # -- subscribing ------------------------------------------------------------------------------------
    def _scan(self) -> None:
        if not self.recording.is_set():
            if not (self.wall_time or stamp_ns(self.node.now()) > 0):
                if not self._waiting_told:
                    self._waiting_told = True
                    self.node.info("record: waiting for the first /clock (simulation time) before recording "
                                   "(--no-sim-time records on wall time)")
                return
            self.recording.set()
        types = self.node.topic_types()
        for topic in self.topics:
            if topic in self._subs or not types.get(topic):
                continue
            got = self.node.subscribe_raw(topic, types[topic],
                                          lambda data, info, t=topic: self._on_message(t, data, info))
            if got is None:  # no publisher now (ROS 2 finds the publishers on the graph)
                continue
            sub, info = got
            if info is not None and not self.writer.has_topic(topic):  # known before the first message (ROS 2)
                try:
                    self._add_topic(topic, info)
                except BaseException:
                    self.node.close(sub)
                    raise
            self._subs[topic] = sub
            qos = f", {info.qos}" if info is not None and info.qos else ""
            self.node.info(f"record: {topic} ({types[topic]}{qos})")

    def _add_topic(self, topic: str, info: RawTopic) -> None:
        self.writer.add_topic(topic, info.type, msgdef=info.definition, digest=info.digest, latched=info.latched,
                              qos=[_rosbags_qos(q) for q in info.offered_qos] or None)

    def _on_message(self, topic: str, data: bytes, info: RawTopic) -> None:
        if self._stop.is_set():
            return
        try:
            if not self.writer.has_topic(topic):  # ROS 1: the connection header tells the type, MD5, definition
                self._add_topic(topic, info)
            self.writer.write_raw(topic, data, self._stamp())
        except Exception as e:  # noqa: BLE001 - count, log, keep recording the rest
            self.errors += 1
            self.node.warn(f"record: {topic}: {e}", throttle=5.0)


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
