"""The agent node: thin rospy wiring around :class:`robotatfactory.agent.behaviour.RoundAgent`.

Uses only what a real robot has. Subscribes (relative names): ``pose``
(geometry_msgs/PoseWithCovarianceStamped, base_link in map, from ``raf localize``), ``odom``
(nav_msgs/Odometry, only to tell that the robot's own sensors are alive) and ``contact`` (std_msgs/Bool).
Never ``ground_truth`` nor simulator state. Publishes ``cmd_vel`` (geometry_msgs/Twist), ``electromagnet``
(std_msgs/Bool), ``agent/path`` (nav_msgs/Path, the path being followed, map frame) and ``/diagnostics``.
Talks to the factory-state server over UDP (a thread polls it whenever the agent asks; the control loop
never waits on the network).

Every control period (the robot's, 40 ms, ROS time: simulation time under ``/use_sim_time``) it steps the
agent with the latest pose brought forward to now with odometry's speeds (:mod:`..agent.predict`), or with None when the pose or odometry is older than ``max_input_age``
seconds (the agent then brakes to a stop). Bad messages are counted and skipped.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist
from nav_msgs.msg import Odometry, Path
from std_msgs.msg import Bool

from ..agent.behaviour import RoundAgent
from ..agent.client import FactoryClient, ServerReplyError, ServerTimeout
from ..agent.predict import extrapolate
from ..field import load_field
from ..robot import load_robot
from ..simtwo.ports import SERVER_UDP_PORT
from . import messages as rm

SUBSCRIBED = ("pose", "odom", "contact")  # the only inputs; a test checks no other is subscribed


@dataclass(frozen=True)
class AgentNodeConfig:
    """The node's settings: field and robot names, the server's address, the staleness limit (s)."""

    field: str = "rules2026"
    robot: str = "simtwo"
    server_host: str = "127.0.0.1"
    server_port: int = SERVER_UDP_PORT
    max_input_age: float = 0.5
    map_frame: str = "map"


class AgentNode:
    def __init__(self, cfg: AgentNodeConfig):
        self.cfg = cfg
        self.field = load_field(cfg.field)
        self.robot = load_robot(cfg.robot)
        self.agent = RoundAgent(self.field, self.robot)
        self.lock = threading.RLock()
        self.pose: tuple[float, float, float] | None = None
        self.pose_stamp = -math.inf
        self.odom_stamp = -math.inf
        self.contact = False
        self.twist = (0.0, 0.0)  # (v m/s, w rad/s) from the latest odometry
        self.counts = {"bad_pose": 0, "stale_cycles": 0, "server_errors": 0, "cycles": 0}
        self._stale_at_diag = 0  # stale_cycles at the last diagnostics report
        self._events_logged = 0
        self._path_sent = None
        self._running = False
        self.subscribers: list = []

    def start(self) -> AgentNode:
        self.pub_cmd = rospy.Publisher("cmd_vel", Twist, queue_size=1, tcp_nodelay=True)
        self.pub_magnet = rospy.Publisher("electromagnet", Bool, queue_size=1, tcp_nodelay=True)
        self.pub_path = rospy.Publisher("agent/path", Path, queue_size=1, latch=True)
        self.pub_diag = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=5)
        self.subscribers = [
            rospy.Subscriber("pose", PoseWithCovarianceStamped, self.on_pose, queue_size=5, tcp_nodelay=True),
            rospy.Subscriber("odom", Odometry, self.on_odom, queue_size=5, tcp_nodelay=True),
            rospy.Subscriber("contact", Bool, self.on_contact, queue_size=5, tcp_nodelay=True),
        ]
        self.client = FactoryClient(self.cfg.server_host, self.cfg.server_port, timeout=0.2, retries=2)
        self._running = True
        self._poller = threading.Thread(target=self._poll_loop, name="raf-agent-server", daemon=True)
        self._poller.start()
        self.timer = rospy.Timer(rospy.Duration(self.robot.control_period), self._tick)
        return self

    def stop(self) -> None:
        self._running = False
        try:
            self.timer.shutdown()
            self.pub_cmd.publish(Twist())
        except Exception:  # noqa: BLE001 - shutting down
            pass
        self.client.close()

    # ------------------------------------------------------------------ inputs
    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        x, y, th = p.position.x, p.position.y, rm.quaternion_yaw(p.orientation)
        if not all(math.isfinite(v) for v in (x, y, th)):
            self.counts["bad_pose"] += 1
            return
        with self.lock:
            self.pose, self.pose_stamp = (x, y, th), msg.header.stamp.to_sec()

    def on_odom(self, msg: Odometry) -> None:
        with self.lock:
            self.odom_stamp = msg.header.stamp.to_sec()
            self.twist = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)

    def on_contact(self, msg: Bool) -> None:
        with self.lock:
            self.contact = bool(msg.data)

    # ------------------------------------------------------------------ server
    def _poll_loop(self) -> None:
        while self._running and not rospy.is_shutdown():
            if self.agent.wants_state:
                try:
                    st = self.client.poll_state()
                except (ServerTimeout, ServerReplyError, OSError) as e:
                    self.counts["server_errors"] += 1
                    rospy.logwarn_throttle(5.0, f"raf agent: factory-state server: {e}")
                    st = None
                if st is not None:
                    with self.lock:
                        self.agent.on_state(st, rospy.get_time())
            time.sleep(0.02)

    # ------------------------------------------------------------------ control
    def _tick(self, _event=None) -> None:
        now = rospy.get_time()
        with self.lock:
            fresh = (now - self.pose_stamp <= self.cfg.max_input_age and now - self.odom_stamp <= self.cfg.max_input_age)
            # the estimate brought forward to now with the measured speeds (the EKF's stamp is older)
            pose = extrapolate(self.pose, *self.twist, min(now - self.pose_stamp, self.cfg.max_input_age)) \
                if fresh and self.pose is not None else None
            if pose is None:
                self.counts["stale_cycles"] += 1
            cmd = self.agent.step(now, pose, self.contact)
            self.counts["cycles"] += 1
            events = self.agent.events[self._events_logged:]
            self._events_logged = len(self.agent.events)
            path = self.agent.path
        tw = Twist()
        tw.linear.x, tw.angular.z = cmd.v, cmd.w
        self.pub_cmd.publish(tw)
        self.pub_magnet.publish(Bool(data=cmd.magnet))
        for t, text in events:
            rospy.loginfo(f"raf agent: t = {t:.2f} s: {text}")
        if path is not None and path is not self._path_sent:
            self._path_sent = path
            self.pub_path.publish(self._path_msg(path))
        if self.counts["cycles"] % 25 == 0:
            self.pub_diag.publish(self._diagnostics())

    def _path_msg(self, path) -> Path:
        msg = Path()
        msg.header.frame_id = self.cfg.map_frame
        msg.header.stamp = rospy.Time.now()
        for x, y in path.points:
            ps = PoseStamped()
            ps.header = msg.header
            ps.pose.position.x, ps.pose.position.y = x, y
            ps.pose.orientation.w = 1.0
            msg.poses.append(ps)
        return msg

    def _diagnostics(self) -> DiagnosticArray:
        a = self.agent
        # WARN while inputs went stale since the last report (not for good once they were stale at start-up)
        stale_now = self.counts["stale_cycles"] - self._stale_at_diag
        self._stale_at_diag = self.counts["stale_cycles"]
        level = DiagnosticStatus.WARN if stale_now and a.mode not in ("done", "wait_start") else DiagnosticStatus.OK
        values = {"mode": a.mode, "task": str(a.task), **{k: v for k, v in self.counts.items()},
                  **vars(a.counters)}
        arr = DiagnosticArray()
        arr.header.stamp = rospy.Time.now()
        st = DiagnosticStatus(level=level, name="raf agent", message=f"{a.mode}: {a.task}", hardware_id="robot")
        from diagnostic_msgs.msg import KeyValue

        st.values = [KeyValue(key=str(k), value=str(v)) for k, v in values.items()]
        arr.status.append(st)
        return arr


def config_from_params(p: dict) -> AgentNodeConfig:
    """The node's settings from its private parameters (``~server_port`` ...); unknown keys are an error."""
    from dataclasses import fields

    from ..errors import ConfigError

    known = {f.name: f.type for f in fields(AgentNodeConfig)}
    unknown = sorted(set(p) - set(known))
    if unknown:
        raise ConfigError(f"unknown agent parameter(s) {', '.join(unknown)} (known: {', '.join(known)})")
    cfg = AgentNodeConfig(**p)
    if not (isinstance(cfg.server_port, int) and 0 < cfg.server_port < 65536):
        raise ConfigError(f"server_port must be 1..65535, got {cfg.server_port!r}")
    if not (isinstance(cfg.max_input_age, (int, float)) and cfg.max_input_age > 0):
        raise ConfigError(f"max_input_age must be > 0 s, got {cfg.max_input_age!r}")
    return cfg


def main(argv: list[str] | None = None) -> int:
    from .cli import spin_node

    return spin_node("raf_agent", lambda node: AgentNode(config_from_params(node.params())).start(), argv)


if __name__ == "__main__":
    import sys

    sys.exit(main())
