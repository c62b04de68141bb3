"""The referee node (``raf referee``): the competition's factory and referee for a simulator that only
reports where things are (the real SimTwo), on either middleware (:mod:`.mw`).

Thin wiring around :class:`robotatfactory.competition.live.LiveReferee`. Subscribes (relative names) to what
the bridge publishes from each SensorFrame: ``ground_truth`` (nav_msgs/Odometry), ``ground_truth/parts``
(geometry_msgs/PoseArray: one per frame, the cycle's clock), ``electromagnet/state`` and ``contact``
(std_msgs/Bool), ``joint_states`` (the encoders, for the trace) and ``cmd_vel``/``electromagnet`` (the
commands, for the trace). Serves the factory-state protocol over UDP (:class:`~..competition.FactoryServer`,
on the simulation clock), and applies the machines' teleports through the bridge's ``sim/place_part``
service from a thread of its own (never from a callback). On stop it prints the referee's final report, the
same text as ``raf sim``'s; with ``end_after_max`` it stops itself once the maximum score has stood that
long (simulation seconds).
"""
from __future__ import annotations

import math
import queue
import threading
from collections import OrderedDict
from dataclasses import dataclass

from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped, Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from ..competition import FactoryServer, RoundSetup
from ..competition.live import LiveReferee
from ..errors import ConfigError
from ..field import load_field
from ..robot import load_robot
from ..simtwo.ports import SERVER_UDP_PORT
from ..simtwo.teleport import plate_facing
from .messages import quaternion_yaw
from .mw import QoS, api
from .mw.base import Node, stamp_ns

KEEP_STAMPS = 50  # ground-truth messages kept to pair with the parts message of the same stamp


@dataclass
class RefereeConfig:
    """The node's settings (ROS parameters of the same names)."""

    field: str = "rules2026"  # the project's default field (SimTwo's scene: simtwo2022)
    robot: str = "simtwo"
    round: int = 1
    seed: int = 0
    parts: str = ""  # incoming parts, slot 1 first (e.g. "RGBX"); "": the seeded draw
    duration: float = 600.0  # s of the round
    start_after: float = 3.0  # simulation s after the first frame before the run starts
    # a topic (relative name, geometry_msgs/PoseWithCovarianceStamped) whose first message says the robot is ready
    # (its localization's pose): the run starts no earlier (nor later than live.READY_TIMEOUT s); "": no wait
    ready_topic: str = ""
    server_host: str = "127.0.0.1"
    server_port: int = SERVER_UDP_PORT
    trace: str = ""  # file for the ground-truth trace (raf sim --trace format); "": none
    end_after_max: float = -1.0  # simulation s the maximum score must stand before the node stops; < 0: never
    status_every: float = 5.0  # simulation s between status lines; 0: none
    place_part_service: str = "sim/place_part"


def config_from_params(p: dict) -> RefereeConfig:
    """The settings from the node's private parameters; unknown keys and bad values are errors."""
    from dataclasses import fields

    known = {f.name for f in fields(RefereeConfig)}
    unknown = sorted(set(p) - known)
    if unknown:
        raise ConfigError(f"unknown referee parameter(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})")
    cfg = RefereeConfig(**p)
    if cfg.round not in (1, 2, 3):
        raise ConfigError(f"round must be 1, 2 or 3, got {cfg.round!r}")
    if not (isinstance(cfg.server_port, int) and 0 <= cfg.server_port < 65536):
        raise ConfigError(f"server_port must be 0..65535, got {cfg.server_port!r}")
    if not isinstance(cfg.ready_topic, str):
        raise ConfigError(f"ready_topic must be a topic name or empty, got {cfg.ready_topic!r}")
    for name in ("duration", "start_after", "status_every"):
        v = getattr(cfg, name)
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
            raise ConfigError(f"{name} must be a number of seconds >= 0, got {v!r}")
    return cfg


class RefereeNode:
    """See the module docstring: ``start()`` subscribes and serves, ``stop()`` prints the final report."""

    def __init__(self, cfg: RefereeConfig, node: Node):
        self.cfg, self.node = cfg, node
        self.field, self.robot = load_field(cfg.field), load_robot(cfg.robot)
        self.setup = RoundSetup.make(cfg.round, cfg.seed, cfg.parts or None, duration=cfg.duration)
        self.live = LiveReferee(self.field, self.robot, self.setup, start_after=cfg.start_after,
                                trace=cfg.trace or None, seed=cfg.seed, wait_ready=bool(cfg.ready_topic))
        self.lock = threading.Lock()
        self.gt: OrderedDict[int, tuple[float, float, float]] = OrderedDict()
        self.enc = (0, 0)
        self.magnet = self.contact = False
        self.cmd = [0.0, 0.0, False]
        self.counts = {"cycles": 0, "no_pose": 0, "teleports": 0, "teleport_failures": 0}
        self._teleports: queue.Queue = queue.Queue()
        self._next_status = 0.0
        self._announced = set()
        self._stopped = threading.Event()
        self.server = FactoryServer(self.live.factory, cfg.server_host, cfg.server_port, self._clock)

    def _clock(self) -> float:
        t = self.live.t
        return 0.0 if t is None else t

    def start(self) -> "RefereeNode":
        node = self.node
        self.subs = [node.subscribe("ground_truth", Odometry, self.on_ground_truth, QoS.RELIABLE, 20),
                     node.subscribe("joint_states", JointState, self.on_joints, QoS.RELIABLE, 5),
                     node.subscribe("electromagnet/state", Bool, self.on_magnet, QoS.RELIABLE, 5),
                     node.subscribe("contact", Bool, self.on_contact, QoS.RELIABLE, 5),
                     node.subscribe("cmd_vel", Twist, self.on_cmd, QoS.RELIABLE, 5),
                     node.subscribe("electromagnet", Bool, self.on_magnet_cmd, QoS.RELIABLE, 5),
                     node.subscribe("ground_truth/parts", PoseArray, self.on_parts, QoS.RELIABLE, 20)]
        if self.cfg.ready_topic:
            self.subs.append(node.subscribe(self.cfg.ready_topic, PoseWithCovarianceStamped, self.on_ready,
                                            QoS.RELIABLE, 1))
        self.server.start()
        self._worker = threading.Thread(target=self._teleporter, name="raf-referee-teleports", daemon=True)
        self._worker.start()
        return self

    def stop(self) -> None:
        if self._stopped.is_set():
            return
        self._stopped.set()
        self._teleports.put(None)
        for s in getattr(self, "subs", []):
            self.node.close(s)
        self.server.stop()
        with self.lock:
            report = self.live.report()
            self.live.close()
        print(str(report), flush=True)
        c = self.counts
        print(f"raf referee: {c['cycles']} cycles, {c['teleports']} teleports ({c['teleport_failures']} failed), "
              f"{c['no_pose']} cycles without a matching ground truth", flush=True)

    # ------------------------------------------------------------------------------------------- inputs
    def on_ground_truth(self, msg: Odometry) -> None:
        p = msg.pose.pose
        with self.lock:
            self.gt[stamp_ns(msg.header.stamp)] = (p.position.x, p.position.y, quaternion_yaw(p.orientation))
            while len(self.gt) > KEEP_STAMPS:
                self.gt.popitem(last=False)

    def on_joints(self, msg: JointState) -> None:
        if len(msg.position) >= 2:
            k = self.robot.ticks_per_rev / (2 * math.pi)
            self.enc = (int(round(msg.position[0] * k)), int(round(msg.position[1] * k)))

    def on_ready(self, msg: PoseWithCovarianceStamped) -> None:
        with self.lock:
            first = not self.live.ready
            self.live.set_ready()
            t = self.live.t
        if first:
            self.node.info(f"raf referee: the robot is ready (a message on {self.cfg.ready_topic}) at t = "
                           f"{0.0 if t is None else t:.2f} s")

    def on_magnet(self, msg: Bool) -> None:
        self.magnet = bool(msg.data)

    def on_contact(self, msg: Bool) -> None:
        self.contact = bool(msg.data)

    def on_cmd(self, msg: Twist) -> None:
        self.cmd[0], self.cmd[1] = msg.linear.x, msg.angular.z

    def on_magnet_cmd(self, msg: Bool) -> None:
        self.cmd[2] = bool(msg.data)

    def on_parts(self, msg: PoseArray) -> None:
        ns = stamp_ns(msg.header.stamp)
        t = ns * 1e-9
        # ground_truth/parts carries the simulator's heading of each part's body (SimTwo's: the plate's + pi/2,
        # docs/protocol.md); the referee and its trace speak of the plate's facing, as raf sim's trace does
        parts = tuple((p.position.x, p.position.y, plate_facing(quaternion_yaw(p.orientation))) for p in msg.poses)
        with self.lock:
            pose = self.gt.get(ns)
            if pose is None:  # the same frame's ground truth not here yet: the latest one
                self.counts["no_pose"] += 1
                pose = next(reversed(self.gt.values()), None)
            if pose is None or self._stopped.is_set():
                return
            self.counts["cycles"] += 1
            started = self.live.factory.started
            teleports = self.live.cycle(t, self.counts["cycles"], pose, parts, self.magnet, self.contact,
                                        self.enc, tuple(self.cmd))
            report = self.live.report() if (self.cfg.status_every and t >= self._next_status) else None
            max_held = self.cfg.end_after_max >= 0 and self.live.max_held_for(self.cfg.end_after_max)
            over = self.live.over()
        if not started and self.live.factory.started:
            self.node.info(f"raf referee: run started at t = {t:.2f} s" + (
                f" (the robot never said it was ready on {self.cfg.ready_topic})" if self.live.started_unready
                else ""))
        for tp in teleports:
            self._teleports.put(tp)
        if report is not None:
            self._next_status = t + self.cfg.status_every
            self.node.info(f"raf referee: t = {t:.1f} s: {report.short()}")
        if max_held and "max" not in self._announced:
            self._announced.add("max")
            self.node.info(f"raf referee: the maximum score has stood {self.cfg.end_after_max:g} s: stopping")
            self.node.shutdown("maximum score held")
        if over and "over" not in self._announced:
            self._announced.add("over")
            self.node.info(f"raf referee: round over at t = {t:.2f} s")

    # ----------------------------------------------------------------------------------------- teleports
    def _teleporter(self) -> None:
        srv = api().srv_types()
        while True:
            tp = self._teleports.get()
            if tp is None:
                return
            try:
                r = self.node.call(self.cfg.place_part_service, srv.PlacePart, timeout=5.0, part=int(tp.part_id),
                                   slot=tp.slot.name, x=0.0, y=0.0, facing=0.0, type="", remove=False)
                ok, text = bool(r.success), r.message
            except Exception as e:  # noqa: BLE001 - a failed call is counted and logged; the referee goes on
                ok, text = False, f"{type(e).__name__}: {e}"
            self.counts["teleports" if ok else "teleport_failures"] += 1
            (self.node.info if ok else self.node.warn)(
                f"raf referee: part {tp.part_id} -> {tp.slot.name} (now {tp.new_type.letter}): "
                f"{'done' if ok else 'FAILED'}: {text}")


def default_params() -> dict:
    from dataclasses import asdict

    return asdict(RefereeConfig())


def node_params(node: Node, given: dict | None = None) -> dict:
    return node.params(default_params(), lambda name: ("", None), given)


def main(argv: list[str] | None = None) -> int:
    from .cli import spin_node

    return spin_node("raf_referee", lambda node: RefereeNode(config_from_params(node_params(node)), node).start(),
                     argv)


if __name__ == "__main__":
    import sys

    sys.exit(main())
