"""The agent node: thin wiring around :class:`robotatfactory.agent.behaviour.RoundAgent`, on either
middleware (:mod:`.mw`).

Uses only what a real robot has. Subscribes (relative names): ``pose``
(geometry_msgs/PoseWithCovarianceStamped, base_link in map, from ``raf localize``), ``odom``
(nav_msgs/Odometry, only to tell that the robot's own sensors are alive), ``contact`` (std_msgs/Bool) and
``scan`` (sensor_msgs/LaserScan from the bridge, handed to the agent as a :class:`~..agent.refind.Scan`: it looks
for a part that fell off the magnet in it). Never ``ground_truth`` nor simulator state. Publishes ``cmd_vel`` (geometry_msgs/Twist), ``electromagnet``
(std_msgs/Bool), ``agent/path`` (nav_msgs/Path, the path being followed, map frame), ``agent/markers``
(visualization_msgs/MarkerArray, map frame: the planned round as arrows from source to destination slot with
their order and part, the current task highlighted, the current goal pose) and ``/diagnostics``.
Talks to the factory-state server over UDP (a thread polls it whenever the agent asks; the control loop
never waits on the network).

Every control period (the robot's, 40 ms, ROS time: simulation time under ``/use_sim_time``) it steps the
agent with the latest pose brought forward to now with odometry's speeds (:mod:`..agent.predict`), or with
None when the pose or odometry is older than ``max_input_age`` seconds (the agent then brakes to a stop). Bad
messages are counted and skipped. Its settings, the round agent's included, are one
:class:`~..agent.settings.AgentSettings`, read from the node's parameters.
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Point, PoseStamped, PoseWithCovarianceStamped, Twist
from nav_msgs.msg import Odometry, Path
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Bool
from visualization_msgs.msg import Marker, MarkerArray

from ..agent.behaviour import RoundAgent
from ..agent.client import FactoryClient, ServerReplyError, ServerTimeout
from ..agent.footprint import pose_in_front
from ..agent.predict import InFlight, extrapolate
from ..agent.refind import Scan
from ..agent.settings import AgentSettings, agent_settings
from ..agent.tasks import Move, Wait, plan_round
from ..field import load_field
from ..robot import load_robot
from ..settings import describer
from . import messages as rm
from .mw import QoS
from .mw.base import OK, WARN, Node

SUBSCRIBED = ("pose", "odom", "contact", "scan")  # the only inputs; a test checks no other is subscribed


class AgentNode:
    """The agent on a middleware node (:mod:`.mw`): ``start()`` subscribes, publishes and starts the control
    timer (node clock), ``stop()`` stops the robot."""

    def __init__(self, cfg: AgentSettings, node: Node):
        self.cfg = cfg
        self.node = node
        self.field = load_field(cfg.field)
        self.robot = load_robot(cfg.robot)
        self.agent = RoundAgent(self.field, self.robot, cfg)
        took = self.agent.prepare()  # the leg-time table (tasks.plan_order) before the node says it runs
        if took > 1.0:
            node.info(f"raf agent: leg-time table measured in {took:.0f} s (cached for the next start)")
        self.lock = threading.RLock()
        self.pose: tuple[float, float, float] | None = None
        self.pose_cov: np.ndarray | None = None  # 3x3 (x, y, theta) of the latest pose
        self.pose_stamp = -math.inf
        self.odom_stamp = -math.inf
        self.contact = False
        self.scan: Scan | None = None  # the latest LIDAR sweep not yet handed to the agent
        self.twist = (0.0, 0.0)  # (v m/s, w rad/s) from the latest odometry
        self.in_flight = InFlight(cfg.command_latency, self.robot.control_period)  # commands sent, not yet run
        self.counts = {"bad_pose": 0, "stale_cycles": 0, "server_errors": 0, "cycles": 0}
        self._stale_at_diag = 0  # stale_cycles at the last diagnostics report
        self._events_logged = 0
        self._path_sent = None
        self._markers_key = None  # what the last agent/markers showed (plan, task, goal)
        self._plan: list = []  # the Moves planned after the current one
        self._plan_state = None  # (server state, current Move) they were planned from
        self._running = False
        self.subscribers: list = []
        self.timer = None
        self.pacer = None  # paced (pace.enabled): cycles come from the paces, not from a timer

    def start(self) -> AgentNode:
        node = self.node
        paced = self.cfg.pace.enabled
        depth = 10 if paced else 1  # paced: every command counts (pace.py), none may be replaced in a queue
        self.pub_cmd = node.publisher("cmd_vel", Twist, QoS.CONTROL, depth)
        self.pub_magnet = node.publisher("electromagnet", Bool, QoS.CONTROL, depth)
        self.pub_path = node.publisher("agent/path", Path, QoS.LATCHED, 1)
        self.pub_markers = node.publisher("agent/markers", MarkerArray, QoS.LATCHED, 1)
        self.pub_diag = node.publisher("/diagnostics", DiagnosticArray, QoS.RELIABLE, 5)
        self.subscribers = [
            node.subscribe("pose", PoseWithCovarianceStamped, self.on_pose, QoS.RELIABLE, 5),
            node.subscribe("odom", Odometry, self.on_odom, QoS.RELIABLE, 5),
            node.subscribe("contact", Bool, self.on_contact, QoS.RELIABLE, 5),
            # paced: every scan counts (the bridge publishes them reliably then)
            node.subscribe("scan", LaserScan, self.on_scan, QoS.RELIABLE if paced else QoS.SENSOR, 2),
        ]
        self.client = FactoryClient(self.cfg.server.host, self.cfg.server.port, timeout=0.2, retries=2)
        self._running = True
        if paced:  # one cycle per paced frame, on the bridge's and the localization's paces (docs/pacing.md)
            from .pace import Pacer

            self.pacer = Pacer(node, "agent", {"bridge": ("odom", "contact", "scan"), "localization": ("pose",)},
                               on_cycle=self._paced_tick, timeout=self.cfg.pace.timeout)
            return self
        self._poller = threading.Thread(target=self._poll_loop, name="raf-agent-server", daemon=True)
        self._poller.start()
        self.timer = node.timer(self.robot.control_period, self._tick)
        return self

    def stop(self) -> None:
        running, self._running = self._running, False
        try:
            self.node.close(self.timer)
            if running:
                self.pub_cmd.publish(Twist())
        except Exception:  # noqa: BLE001 - shutting down
            pass
        if hasattr(self, "client"):
            self.client.close()

    # ------------------------------------------------------------------ inputs
    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        x, y, th = p.position.x, p.position.y, rm.quaternion_yaw(p.orientation)
        if not all(math.isfinite(v) for v in (x, y, th)):
            self.counts["bad_pose"] += 1
            self._got("pose")
            return
        c = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[np.ix_((0, 1, 5), (0, 1, 5))]
        with self.lock:
            self.pose, self.pose_stamp = (x, y, th), rm.stamp_to_s(msg.header.stamp)
            self.pose_cov = c if np.all(np.isfinite(c)) else None
        self._got("pose")

    def on_odom(self, msg: Odometry) -> None:
        with self.lock:
            self.odom_stamp = rm.stamp_to_s(msg.header.stamp)
            self.twist = (msg.twist.twist.linear.x, msg.twist.twist.angular.z)
        self._got("odom")

    def on_contact(self, msg: Bool) -> None:
        with self.lock:
            self.contact = bool(msg.data)
        self._got("contact")

    def on_scan(self, msg: LaserScan) -> None:
        scan = scan_from_msg(msg)
        with self.lock:
            self.scan = scan
        self._got("scan")

    def _got(self, key: str) -> None:
        if self.pacer is not None:
            self.pacer.got(key)

    # ------------------------------------------------------------------ server
    def _poll_loop(self) -> None:
        while self._running and self.node.ok():
            self._poll_state(self.node.now_s)
            time.sleep(0.02)

    def _poll_state(self, now) -> None:
        """Ask the factory-state server if the agent wants its state; hand it over stamped ``now()`` (node clock)."""
        if not self.agent.wants_state:
            return
        try:
            st = self.client.poll_state()
        except (ServerTimeout, ServerReplyError, OSError) as e:
            self.counts["server_errors"] += 1
            self.node.warn(f"raf agent: factory-state server: {e}", throttle=5.0)
            return
        if st is not None:
            with self.lock:
                self.agent.on_state(st, now())

    # ------------------------------------------------------------------ control
    def _paced_tick(self, t: float) -> None:
        """Paced: the cycle of the frame stamped ``t``. The simulator waits for this cycle's command, so the
        factory-state server answers with its state at ``t``."""
        if not self._running:
            return
        self._poll_state(lambda: t)
        self._tick(now=t)
        self.pacer.sent("cmd_vel")
        self.pacer.sent("electromagnet")
        self.pacer.done(t)

    def _tick(self, _event=None, now: float | None = None) -> None:
        if not self._running:
            return
        now = self.node.now_s() if now is None else now
        with self.lock:
            age = self.cfg.max_input_age
            fresh = now - self.pose_stamp <= age and now - self.odom_stamp <= age
            # the estimate brought forward to now with the measured speeds (the EKF's stamp is older), then
            # through the commands in flight: the pose when this cycle's command will start to act
            pose = self.in_flight.ahead(extrapolate(self.pose, *self.twist, min(now - self.pose_stamp,
                                                                                self.cfg.max_input_age)), now) \
                if fresh and self.pose is not None else None
            if pose is None:
                self.counts["stale_cycles"] += 1
            if self.scan is not None:  # (paced: the frame's sweep is in, the pace counted it)
                self.agent.on_scan(self.scan)
                self.scan = None
            cmd = self.agent.step(now, pose, self.contact, uncertainty=self.pose_cov if pose is not None else None)
            self.counts["cycles"] += 1
            self.in_flight.sent(now, float(cmd.v), float(cmd.w))
            events = self.agent.events[self._events_logged:]
            self._events_logged = len(self.agent.events)
            path = self.agent.path
        tw = Twist()
        tw.linear.x, tw.angular.z = float(cmd.v), float(cmd.w)
        self.pub_cmd.publish(tw)
        self.pub_magnet.publish(Bool(data=bool(cmd.magnet)))
        for t, text in events:
            self.node.info(f"raf agent: t = {t:.2f} s: {text}")
        if path is not None and path is not self._path_sent:
            self._path_sent = path
            self.pub_path.publish(self._path_msg(path))
        if self.counts["cycles"] % 5 == 0:  # 5 Hz at most, and only when something shown changed
            self._publish_markers()
        if self.counts["cycles"] % 25 == 0:
            self.pub_diag.publish(self._diagnostics())

    def _path_msg(self, path) -> Path:
        msg = Path()
        msg.header.frame_id = self.cfg.map_frame
        msg.header.stamp = self.node.now()
        for x, y in path.points:
            ps = PoseStamped()
            ps.header = msg.header
            ps.pose.position.x, ps.pose.position.y = float(x), float(y)
            ps.pose.orientation.w = 1.0
            msg.poses.append(ps)
        return msg

    # ------------------------------------------------------------------ RViz
    def _current_move(self) -> Move | None:
        """The Move being done now, with the destination the agent is heading for (it may have changed it
        since it picked the part), or None."""
        a = self.agent
        if not isinstance(a.task, Move):
            return None
        if a.carrying is not None and a.target is not None:
            return Move(a.task.part, a.task.source, a.target)
        return a.task

    def _planned_moves(self, current: Move | None) -> list:
        """The round as planned: the current Move first, then the agent's own order of the moves after it
        (``tasks.plan_order``), else the Moves :func:`..agent.tasks.plan_round` plans from the server state as it
        will be once the current one is done. Re-planned only when the
        server state or the current Move changes."""
        a = self.agent
        st = a.state
        if st is None:
            return [current] if current is not None else []
        key = (id(st), current, id(a.order))
        if key != self._plan_state:
            self._plan_state = key
            if current is not None:  # the part leaves its slot (it may be gone already) and lands at the target
                st = st.with_slot(current.source, None).with_slot(current.target, current.part)
            try:
                if a.order is not None and a.order.moves and a.order.moves[0] == current:  # the agent's own order
                    self._plan = list(a.order.moves[1:])
                else:
                    steps, _ = plan_round(a.policy, st, a.delays.estimate or 10.0)
                    self._plan = [s.task for s in steps if isinstance(s.task, Move)]
            except Exception as e:  # noqa: BLE001 - display only: a plan that cannot be made shows nothing
                self._plan = []
                self.node.warn(f"raf agent: no plan to show: {e}", throttle=10.0)
        return ([current] if current is not None else []) + self._plan

    def _goal(self):
        """The current goal pose (x, y, heading; m, rad) in map: the path's end facing the slot's plate while
        driving, the dock pose while docking; None when there is none."""
        a = self.agent
        if a.target is None or a.mode not in ("to_pick", "to_place", "pick", "place"):
            return None
        slot = self.field.slot(a.target.zone, a.target.number)
        if a.mode in ("to_pick", "to_place") and a.path is not None and len(a.path.points):
            x, y = (float(v) for v in a.path.points[-1])  # the approach pose, facing the plate
            return x, y, float(slot.facing) + math.pi
        return tuple(float(v) for v in pose_in_front(slot, a.d_dock))  # docking: the dock pose

    def _publish_markers(self) -> None:
        with self.lock:
            a = self.agent
            current = self._current_move()
            moves = self._planned_moves(current)
            task = current if current is not None else (a.task if isinstance(a.task, Wait) else None)
            goal = self._goal()
            mode = a.mode
        key = (tuple(moves), task, goal, mode)
        if key == self._markers_key:
            return
        self._markers_key = key
        self.pub_markers.publish(self.marker_array(moves, task, goal, mode))

    def marker_array(self, moves: list, task, goal, mode: str) -> MarkerArray:
        """The plan, the current task and the goal as RViz markers (map frame; namespaces ``agent_plan``,
        ``agent_plan_text``, ``agent_task``, ``agent_goal``). The first marker deletes the previous set."""
        frame, stamp = self.cfg.map_frame, self.node.now()
        out = MarkerArray()
        out.markers.append(Marker(action=Marker.DELETEALL))

        def marker(ns, mid, mtype, rgba, scale):
            m = Marker(ns=ns, id=mid, type=mtype, action=Marker.ADD)
            m.header.frame_id, m.header.stamp = frame, stamp
            m.pose.orientation.w = 1.0
            m.scale.x, m.scale.y, m.scale.z = (float(v) for v in scale)
            m.color.r, m.color.g, m.color.b, m.color.a = (float(v) for v in rgba)
            return m

        def xy(ref):
            s = self.field.slot(ref.zone, ref.number)
            return float(s.xy[0]), float(s.xy[1])

        current = task if isinstance(task, Move) else None
        for i, mv in enumerate(moves):
            (x0, y0), (x1, y1) = xy(mv.source), xy(mv.target)
            is_current = i == 0 and mv == current
            z = 0.06 if is_current else 0.04
            arrow = marker("agent_plan", i, Marker.ARROW, (1.0, 0.2, 0.9, 1.0) if is_current else (0.3, 0.3, 0.9, 0.6),
                           (0.012 if is_current else 0.006, 0.03 if is_current else 0.018, 0.03))
            arrow.points = [Point(x=x0, y=y0, z=z), Point(x=x1, y=y1, z=z)]
            out.markers.append(arrow)
            text = marker("agent_plan_text", i, Marker.TEXT_VIEW_FACING, (1.0, 1.0, 1.0, 1.0),
                          (0.0, 0.0, 0.04 if is_current else 0.03))
            text.pose.position.x, text.pose.position.y, text.pose.position.z = (x0 + x1) / 2, (y0 + y1) / 2, z + 0.05
            text.text = f"{i + 1}: {mv.part.label} {mv.source} -> {mv.target}"
            out.markers.append(text)
        head = marker("agent_task", 0, Marker.TEXT_VIEW_FACING, (1.0, 0.9, 0.2, 1.0), (0.0, 0.0, 0.06))
        fx, fy = self.field.floor.x, self.field.floor.y
        head.pose.position.x, head.pose.position.y = (fx[0] + fx[1]) / 2, float(fy[1]) + 0.1
        head.pose.position.z = 0.1
        head.text = f"{mode}: {task}" if task is not None else {"wait_start": "waiting for the start",
                                                               "done": "round done"}.get(mode, mode)
        out.markers.append(head)
        if current is not None:  # the part being moved: a ring round its source slot
            ring = marker("agent_task", 1, Marker.CYLINDER, (1.0, 0.2, 0.9, 0.35), (0.12, 0.12, 0.01))
            ring.pose.position.x, ring.pose.position.y = xy(current.source)
            out.markers.append(ring)
        if goal is not None:
            g = marker("agent_goal", 0, Marker.ARROW, (0.1, 0.9, 0.2, 1.0), (0.08, 0.015, 0.015))
            g.pose.position.x, g.pose.position.y, g.pose.position.z = goal[0], goal[1], 0.02
            g.pose.orientation = rm.yaw_quaternion(goal[2])
            out.markers.append(g)
        return out

    def _diagnostics(self) -> DiagnosticArray:
        a = self.agent
        # WARN while inputs went stale since the last report (not for good once they were stale at start-up)
        stale_now = self.counts["stale_cycles"] - self._stale_at_diag
        self._stale_at_diag = self.counts["stale_cycles"]
        level = WARN if stale_now and a.mode not in ("done", "wait_start") else OK
        values = {"mode": a.mode, "task": str(a.task), **{k: v for k, v in self.counts.items()},
                  **vars(a.counters)}
        arr = DiagnosticArray()
        arr.header.stamp = self.node.now()
        arr.status.append(rm.diagnostic_status("raf agent", level, f"{a.mode}: {a.task}", "robot",
                                               {k: str(v) for k, v in values.items()}))
        return arr


def scan_from_msg(msg: LaserScan) -> Scan:
    """A LaserScan as the agent takes it (rays at ``angle_min + i * angle_increment`` in the laser frame, ray i
    measured at the stamp + ``i * time_increment``; inf and NaN: no return)."""
    return Scan(rm.stamp_to_s(msg.header.stamp), tuple(msg.ranges), float(msg.angle_min), float(msg.angle_increment),
                float(msg.time_increment), float(msg.range_min), float(msg.range_max))


def config_from_params(p: dict) -> AgentSettings:
    """The node's settings from its private parameters (the tree of :class:`AgentSettings`:
    ``~server/port`` on ROS 1, ``server.port`` on ROS 2); an unknown name or a bad value is a ConfigError."""
    return agent_settings(p)


def main(argv: list[str] | None = None) -> int:
    from .cli import spin_node

    return spin_node("raf_agent", lambda node: AgentNode(config_from_params(node_params(node)), node).start(), argv)


def default_params() -> dict:
    """The node's parameters with their defaults (what ROS 2 declares): every agent setting."""
    from ..settings import tree

    return tree(AgentSettings())


#: (description, (min, max) or None) of a parameter (``dock.approach_speed``): agent/settings.py's
describe_param = describer(AgentSettings)


def node_params(node: Node, given: dict | None = None) -> dict:
    """The node's parameters (ROS 2: declared with their defaults, descriptions and ranges)."""
    return node.params(default_params(), describe_param, given)


if __name__ == "__main__":
    import sys

    sys.exit(main())
