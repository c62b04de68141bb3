"""``raf experiment faults``, the ROS side: this process's node on the rig's graph and what it watches.

:class:`Watch` subscribes to what the bridge publishes (``odom``, ``/clock``, ``joint_states``, TF ``odom ->
base_link``, ``scan``, the camera's images, ``/diagnostics``) and records each message's arrival (wall time),
stamp and values, for the campaign's figures (:mod:`.faults`) and its observer (:mod:`._faults_observe`:
:meth:`Watch.published`); it also drives the robot (``cmd_vel`` from a thread: :meth:`Watch.drive`). Through
the middleware layer (:mod:`..ros.mw`), never rospy or rclpy directly.
"""
from __future__ import annotations

import threading
import time

from ..ros.mw.base import stamp_ns

_NODE = None  # this process's node (experiment_node)


def experiment_node():
    """This process's node on the rig's graph, made on first use: rospy has one node per process, bound to one
    master for good (each part runs in an interpreter of its own: :func:`.faults._part_child`)."""
    global _NODE
    if _NODE is None:
        from ..ros.mw import api

        _NODE = api().init_node("raf_experiment_faults", anonymous=True, signals=False)
    return _NODE


class Watch:
    """This process's node (:func:`experiment_node`): odom, /clock, joint_states, /tf (odom -> base_link),
    scan, camera images, diagnostics in (each with its arrival's wall time and its stamp); ``cmd_vel`` out."""

    def __init__(self, odom_frame: str = "odom", base_frame: str = "base_link"):
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock
        from sensor_msgs.msg import Image, JointState, LaserScan
        from tf2_msgs.msg import TFMessage

        from ..ros.mw import QoS

        self.node = node = experiment_node()
        self.Twist = Twist
        self.lock = threading.Lock()
        self.odom: list[tuple] = []  # (wall, stamp_ms, x, y, theta)
        self.clock: list[tuple] = []  # (wall, stamp_ms)
        self.joints: list[tuple] = []  # (wall, stamp_ms, left rad, right rad)
        self.images: list[tuple] = []  # (wall, stamp_ms)
        self.tf: list[tuple] = []  # (wall, stamp_ms, x, y, theta): odom -> base_link
        self.scans: list[tuple] = []  # (wall, stamp_ms (float: a sweep's stamp is its first ray's time), ranges)
        self.frames = (odom_frame.lstrip("/"), base_frame.lstrip("/"))
        self.diag: dict[str, dict] = {}
        # ROS 1: queue 1 and TCP_NODELAY out; TCP_NODELAY on odom, /clock and joint_states (SYNCHRONOUS), not on
        # the images (RELIABLE: 2 deep, a large buffer) nor /diagnostics
        self.cmd = node.publisher("cmd_vel", Twist, QoS.CONTROL)
        self.subs = [node.subscribe("odom", Odometry, self._odom, QoS.SYNCHRONOUS, 50),
                     node.subscribe("/clock", Clock, self._clock, QoS.SYNCHRONOUS, 50),
                     node.subscribe("joint_states", JointState, self._joints, QoS.SYNCHRONOUS, 50),
                     node.subscribe("/tf", TFMessage, self._tf, QoS.RELIABLE, 100),
                     node.subscribe("scan", LaserScan, self._scan, QoS.SENSOR, 20),
                     node.subscribe("camera/image_raw", Image, self._image, QoS.RELIABLE, 2, large=True),
                     node.subscribe("/diagnostics", DiagnosticArray, self._diag, QoS.RELIABLE, 20)]
        self._drive = None
        self._drive_stop = threading.Event()

    @staticmethod
    def _ms(stamp) -> int:
        return int(round(stamp_ns(stamp) / 1e6))

    def _odom(self, m):
        from ..ros.messages import quaternion_yaw

        with self.lock:
            self.odom.append((time.monotonic(), self._ms(m.header.stamp), m.pose.pose.position.x,
                              m.pose.pose.position.y, quaternion_yaw(m.pose.pose.orientation)))

    def _clock(self, m):
        with self.lock:
            self.clock.append((time.monotonic(), self._ms(m.clock)))

    def _joints(self, m):
        if len(m.position) >= 2:
            with self.lock:
                self.joints.append((time.monotonic(), self._ms(m.header.stamp), m.position[0], m.position[1]))

    def _tf(self, m):
        from ..ros.messages import quaternion_yaw

        now = time.monotonic()
        for t in m.transforms:
            if (t.header.frame_id.lstrip("/"), t.child_frame_id.lstrip("/")) == self.frames:
                with self.lock:
                    self.tf.append((now, self._ms(t.header.stamp), t.transform.translation.x,
                                    t.transform.translation.y, quaternion_yaw(t.transform.rotation)))

    def _scan(self, m):
        import numpy as np

        r = np.asarray(m.ranges, dtype=np.float32)
        with self.lock:
            self.scans.append((time.monotonic(), stamp_ns(m.header.stamp) / 1e6, r))

    def published(self):
        """Everything recorded so far, for :class:`._faults_observe.Observer` (copies)."""
        from ._faults_observe import Published

        with self.lock:
            return Published(odom=list(self.odom), clock=list(self.clock), joints=list(self.joints),
                             tf=list(self.tf), scans=list(self.scans))

    def _image(self, m):
        with self.lock:
            self.images.append((time.monotonic(), self._ms(m.header.stamp)))

    def _diag(self, m):
        from ..ros.messages import diagnostic_values

        with self.lock:
            for st in m.status:
                self.diag[st.name] = diagnostic_values(st) | {"_level": st.level, "_message": st.message}

    def stream_diag(self) -> dict:
        with self.lock:
            for name, d in self.diag.items():
                if name.endswith("sensor stream"):
                    return dict(d)
        return {}

    def drive(self, profile) -> None:
        """Publish cmd_vel = profile(wall seconds since start) at 20 Hz from a thread until stop_drive()."""
        self.stop_drive()
        self._drive_stop.clear()

        def loop():
            t0 = time.monotonic()
            while not self._drive_stop.is_set():
                v, w = profile(time.monotonic() - t0)
                tw = self.Twist()
                tw.linear.x, tw.angular.z = v, w
                self.cmd.publish(tw)
                time.sleep(0.05)

        self._drive = threading.Thread(target=loop, daemon=True)
        self._drive.start()

    def stop_drive(self) -> None:
        if self._drive is not None:
            self._drive_stop.set()
            self._drive.join(2)
            self._drive = None
        for _ in range(3):
            self.cmd.publish(self.Twist())
            time.sleep(0.05)

    def close(self):
        self.stop_drive()
        for s in self.subs:
            self.node.close(s)
