"""``raf experiment localization``'s recording: a private ROS graph (a roscore on a free port / a ROS 2
domain id of its own) with this process's node on it (:func:`experiment_graph`, :class:`Graph`); per drive a
:class:`Session` that starts the simulator (``raf sim`` in the mode's settings, or the real SimTwo teleported
to the route's start), ``raf bridge`` and ``raf localize`` (every method computed) and drives the route with a
:class:`Recorder` (pure pursuit on the GROUND-TRUTH pose, every pose stream recorded); the calibration drive
recorded into a bag (:class:`BagSink`, a ROS 1 bag or a rosbag2) and ``raf calibrate`` run on it
(:func:`calibration_drive`); the robot the stand-in simulates (:func:`sim_robot`).

Reads the plan (:class:`.localization.Plan`) without importing the experiment module (its ``mode``,
``real_simtwo``, ``speed``, ``bag`` and the wheel and camera errors). ROS is imported inside the functions that
use it.
"""
from __future__ import annotations

import contextlib
import math
import shutil
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._localization_analysis import METHODS

if TYPE_CHECKING:
    from ..simtwo_linux.scene import CalibrationConstraints
    from .localization import Plan

#: idealisations of the stand-in for --ideal: (option of raf sim, its value or None, what it does); the results
#: list the ones applied.
IDEAL_SIM_OPTIONS = (
    ("--lockstep", None, "lockstep: the simulator waits for the reply to each frame"),
    ("--lockstep-timeout", "2.0", "lockstep timeout"),
    ("--camera-timing", "grid", "camera frames rendered on the k/15 s grid of simulation time"),
    ("--reply-timing", "every_cycle", "the newest reply read before every cycle"),
    ("--lidar-update", "per_ray", "each LIDAR ray delivered as soon as it is measured"),
    ("--no-lidar-self-hits", None, "LIDAR rays pass through the robot's own wheels"),
    ("--speed-control", "ideal_pi", "the project's own speed PI with feed-forward every 1 ms"),
)
#: bridge settings for --ideal (``--set KEY=VALUE``)
IDEAL_BRIDGE_SETS = (
    ("camera/use_grid", "true", "camera stamps on the render grid"),
    ("camera/bracket", "nearest", "camera frame assigned to the nearer SensorFrame (with the grid: exact stamps)"),
    ("lidar/update", "per_ray", "LIDAR rays assembled one by one"),
)
#: options for the SimTwo-like mode that are not ``raf sim``'s defaults (none: its defaults are SimTwo's)
SIMTWO_SIM_OPTIONS: tuple = ()


# ------------------------------------------------------------------------------------------- recorder


#: the calibration drive keeps a camera frame per this much camera time (s)
IMAGE_PERIOD_S = 0.2


class Recorder:
    """The experiment's recording on this process's node (:class:`~robotatfactory.ros.processes.ExperimentNode`,
    either middleware): drives the route on ground truth and records every pose stream; on the calibration
    drive also camera/image_raw (one frame per ``image_period_s`` of camera time), camera_info and odom into a bag
    (:func:`open_bag_writer`)."""

    def __init__(self, exp, route, speed: float, robot, bag_path: Path | None = None,
                 image_period_s: float = IMAGE_PERIOD_S):
        from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
        from nav_msgs.msg import Odometry

        from ..localization.geometry import inv
        from ..localization.route import PurePursuit
        from ..ros.mw import QoS

        self.exp = exp
        node = exp.node
        self.Twist = Twist
        self.pp = PurePursuit.for_route(route, speed=speed)
        self.T_cam_base = inv(robot.camera.base_to_optical())
        self.lock = threading.Lock()
        self.data = {k: [] for k in ("gt", "odom", "ekf", "camera_pose", "accepted", "rejected", *METHODS)}
        self.last_gt_t = -math.inf
        self.cmd = node.publisher("cmd_vel", Twist, QoS.RELIABLE, 5)
        self.done_t: float | None = None
        Pose = PoseWithCovarianceStamped
        self.subs = [node.subscribe("ground_truth", Odometry, self._on_gt, QoS.SYNCHRONOUS, 50),
                     node.subscribe("odom", Odometry, self._rec("odom"), QoS.RELIABLE, 100),
                     node.subscribe("pose", Pose, self._rec("ekf"), QoS.RELIABLE, 100),
                     node.subscribe("camera_pose", Pose, self._on_camera, QoS.RELIABLE, 50)]
        self.subs += [node.subscribe(f"aruco/fixes/{m}", Pose, self._rec(m), QoS.RELIABLE, 50) for m in METHODS]
        self.subs += [node.subscribe(f"aruco/fixes/filter_{k}", Pose, self._rec(k), QoS.RELIABLE, 100)
                      for k in ("accepted", "rejected")]
        # the calibration drive: camera/image_raw (one frame per image_period_s), camera_info and odom to a bag
        self.bag = None
        if bag_path is not None:
            from sensor_msgs.msg import CameraInfo, Image

            self.bag = bag = BagSink(bag_path, image_period_s)
            self.subs += [node.subscribe("camera/image_raw", Image, bag.image, QoS.SENSOR, 20, large=True),
                          node.subscribe("camera/camera_info", CameraInfo, bag.writer("camera/camera_info",
                                                                                      "camera_info"), QoS.SENSOR, 20),
                          node.subscribe("odom", Odometry, bag.writer("odom", "odom"), QoS.RELIABLE, 100)]
        from diagnostic_msgs.msg import DiagnosticArray

        self.diag: dict[str, str] = {}
        self.subs.append(node.subscribe("/diagnostics", DiagnosticArray, self._on_diag, QoS.RELIABLE, 20))

    @property
    def bag_counts(self) -> dict:
        return dict(self.bag.counts) if self.bag is not None else {"images": 0, "odom": 0, "camera_info": 0}

    def close_bag(self) -> None:
        if self.bag is not None:
            self.bag.close()

    def _on_diag(self, msg):
        from ..ros.messages import diagnostic_values

        for st in msg.status:
            if "raf_localization" in st.name:
                with self.lock:
                    self.diag.update(diagnostic_values(st))

    @staticmethod
    def _planar(msg) -> tuple[float, float, float, float]:
        p = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
        from ..ros.messages import quaternion_yaw

        return (stamp_ns(msg.header.stamp) * 1e-9, p.position.x, p.position.y, quaternion_yaw(p.orientation))

    def _rec(self, key):
        def cb(msg):
            row = self._planar(msg)
            if key in ("ekf", "accepted", "rejected", *METHODS):
                c = np.array(msg.pose.covariance).reshape(6, 6)
                row = row + (c[0, 0], c[1, 1], c[5, 5])
            with self.lock:
                self.data[key].append(row)
        return cb

    def _on_camera(self, msg):
        from scipy.spatial.transform import Rotation

        from ..localization.metrics import base_from_camera

        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        T[:3, 3] = (p.x, p.y, p.z)
        with self.lock:
            self.data["camera_pose"].append((stamp_ns(msg.header.stamp) * 1e-9,) + base_from_camera(T, self.T_cam_base)
                                            + (p.z,))

    def _on_gt(self, msg):
        row = self._planar(msg)
        with self.lock:
            self.data["gt"].append(row)
            self.last_gt_t = row[0]
        if self.done_t is not None:  # route done: keep the robot stopped
            self.cmd.publish(self.Twist())
            return
        v, w = self.pp.command(row[1:])
        if self.pp.done and self.done_t is None:
            self.done_t = row[0]
        cmd = self.Twist()
        cmd.linear.x, cmd.angular.z = v, w
        self.cmd.publish(cmd)

    def stop(self):
        for s in self.subs:
            self.exp.drop(s)
        self.subs = []
        self.exp.drop(self.cmd)
        self.close_bag()

    def arrays(self) -> dict:
        with self.lock:
            return {k: np.array(v, dtype=float) if v else np.zeros((0, 4)) for k, v in self.data.items()}


# ------------------------------------------------------------------------------------------- bags


def stamp_ns(stamp) -> int:
    from ..ros.mw.base import stamp_ns as ns

    return ns(stamp)


class BagSink:
    """The calibration drive's recording: callbacks that write messages to a bag (:func:`open_bag_writer`)
    under global topic names (``/camera/image_raw``), stamped with their header stamps; an image only once
    ``image_period_s`` of header time has passed since the last one kept (a frame in 3 from the stand-in's
    15 fps camera; every frame from a software-rendered SimTwo at 1-9 fps). ``counts``: messages written
    (images, odom, camera_info)."""

    def __init__(self, path: Path, image_period_s: float = IMAGE_PERIOD_S):
        if not image_period_s >= 0:
            raise ValueError(f"image_period_s {image_period_s} must be >= 0")
        self._bag = open_bag_writer(path)
        self._lock = threading.Lock()
        # 5 ms of slack: frames 66.7 ms apart, stamped to the millisecond, are kept every 3rd at 0.2 s
        self._period_ns, self._last_ns = int(image_period_s * 1e9) - 5_000_000, None
        self.counts = {"images": 0, "odom": 0, "camera_info": 0}
        self.closed = False

    def writer(self, topic: str, counter: str):
        def cb(msg):
            with self._lock:
                if not self.closed:
                    self._bag.write("/" + topic.lstrip("/"), msg, stamp_ns(msg.header.stamp))
                    self.counts[counter] += 1
        return cb

    def image(self, msg) -> None:
        t = stamp_ns(msg.header.stamp)
        with self._lock:
            take = self._last_ns is None or t - self._last_ns >= self._period_ns or t < self._last_ns
            if take:
                self._last_ns = t
        if take:
            self.writer("camera/image_raw", "images")(msg)

    def close(self) -> None:
        with self._lock:
            if not self.closed:
                self.closed = True
                self._bag.close()


def open_bag_writer(path: Path):
    """The calibration drive's recording (:func:`robotatfactory.ros.bags.open_writer`): a ROS 1 bag on ROS 1, a
    rosbag2 (MCAP) directory on ROS 2; ``write(topic, msg, stamp_ns)``, ``close()``."""
    from ..ros.bags import default_format, open_writer

    return open_writer(path, default_format())


def _raf(*args: str) -> list[str]:
    from ..ros.processes import raf_cmd

    return raf_cmd(*args)


# ------------------------------------------------------------------------------------------- the drives


def sim_robot(plan: Plan, work: Path):
    """The robot the stand-in simulates (the nominal one with the wheel and camera errors) and its JSON file,
    or (nominal robot, None) when it is the nominal one."""
    from ..robot import load_robot

    nominal = load_robot()
    robot = replace(nominal, track=nominal.track * (1 + plan.track_error),
                    wheel_radius=nominal.wheel_radius * (1 + plan.radius_error))
    if plan.camera_error:
        from ..localization.calibration import perturbed_robot

        robot = perturbed_robot(robot)  # fx, fy +3 %, cx +4 px, cy -3 px, pitch +1 degree
    if robot == nominal:
        return robot, None
    from ..localization.calibration import write_robot_json

    return robot, write_robot_json(robot, work / "robot_sim.json")


@dataclass
class Graph:
    """The run's private ROS graph (a roscore on a free port / a ROS 2 domain id) and this process's node on it."""

    private: object  # robotatfactory.ros.master.PrivateMaster | PrivateDomain
    exp: object  # robotatfactory.ros.processes.ExperimentNode

    def env(self) -> dict:
        return self.private.env()

    @property
    def middleware(self) -> str:
        return self.exp.middleware


class Session:
    """One drive: bridge, localization (optional) and simulator processes on the experiment's graph, and
    this process's recorder. Use as a context manager; ``drive()`` returns when the route is done."""

    def __init__(self, args, plan: Plan, graph: Graph, log_dir: Path, name: str, route, robot_file: Path | None,
                 calibration_file: Path | None, localize: bool = True, bag: Path | None = None,
                 speed: float | None = None, sim_extra: tuple[str, ...] = ()):
        from ..ros.processes import Procs

        self.args, self.plan, self.graph, self.name, self.route = args, plan, graph, name, route
        self.log_dir = log_dir / name
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs = Procs(self.log_dir, watch=("sim", "bridge", "localize"))
        self.robot_file, self.calibration_file, self.localize, self.bag = robot_file, calibration_file, localize, bag
        self.speed = speed if speed is not None else plan.speed
        self.sim_extra = tuple(sim_extra)  # more raf sim options (the competition's world: --round, --set perturb.*)
        self.rec = None
        self.notes: list[str] = []
        self.applied: list[str] = []  # simulator and bridge options applied for the mode

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.rec is not None:
            self.rec.stop()
        self.procs.stop_all()

    def _calibration_args(self) -> list[str]:
        return [] if self.calibration_file is None else ["--calibration", str(self.calibration_file)]

    def _bridge_mode_args(self) -> list[str]:
        if self.plan.mode != "ideal":
            return []
        out = []
        for key, val, _what in IDEAL_BRIDGE_SETS:
            out += ["--set", f"{key}={val}"]
            self.applied.append(f"bridge {key}={val}")
        return out

    def _sim_mode_args(self) -> list[str]:
        out = []
        for opt, val, _what in IDEAL_SIM_OPTIONS if self.plan.mode == "ideal" else SIMTWO_SIM_OPTIONS:
            out += [opt] + ([val] if val is not None else [])
            self.applied.append(opt + (f" {val}" if val is not None else ""))
        return out

    def start(self) -> None:
        from ..ros.master import free_port

        args, env = self.args, self.graph.env()
        import socket

        bport, sport, cport = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM), free_port()
        cam = f"tcp://127.0.0.1:{cport}"
        self.procs.start("bridge", _raf("--field", args.field, "bridge", "--port", str(bport), "--camera", cam,
                                        "--sim-host", "127.0.0.1", *self._calibration_args(),
                                        *self._bridge_mode_args()), env)
        if self.plan.real_simtwo:
            self._start_simtwo(bport, sport, cport)
        if self.localize:
            loc_args = ["--field", args.field, "localize", "--set", "node/all_methods=true",
                        *self._calibration_args()]
            for s_ in args.set:
                loc_args += ["--set", s_]
            self.procs.start("localize", _raf(*loc_args), env)
        if self.plan.real_simtwo:
            return
        time.sleep(3.0)  # let the bridge bind its port before the simulator starts sending
        x0, y0, th0 = self.route.start
        sim_args = ["--field", args.field, "sim", "--port", str(sport), "--bridge", f"127.0.0.1:{bport}",
                    "--camera-bind", cam, "--no-server", f"--start-pose={x0},{y0},{th0}", "--seed", str(args.seed),
                    "--status-every", "5", *self._sim_mode_args()]
        if not args.no_beacons:
            sim_args.append("--beacons")
        sim_args.append("--no-control")  # SimTwo has no control channel; nor a port clash here
        sim_args += self.sim_extra
        if self.robot_file is not None:
            sim_args += ["--robot", str(self.robot_file)]
        self.procs.start("sim", _raf(*sim_args), env)

    def _start_simtwo(self, bport: int, sport: int, cport: int) -> None:
        """The real SimTwo (camera open), then the robot teleported to the route's start through the bridge's
        sim/set_robot_pose (which waits for SimTwo's ground truth to confirm it); before the localization
        starts, so that the filter never sees the jump."""
        from ..ros.mw import api
        from ..ros.processes import wait_until

        args, env = self.args, self.graph.env()
        time.sleep(1.0)  # the bridge binds its port
        robot = ["--robot", str(self.robot_file)] if self.robot_file is not None else []  # its camera, into AGV.xml
        self.procs.start("sim", _raf("--field", args.field, "simtwo", "run", "--port", str(sport), "--bridge",
                                     f"127.0.0.1:{bport}", "--camera-port", str(cport), *robot), env)
        log = self.log_dir / "sim.log"
        wait_until(lambda: log.exists() and "[simtwo] running" in log.read_text(errors="replace"), 180,
                   "SimTwo streaming with its camera", self.procs.check)
        x0, y0, th0 = self.route.start
        r = self.graph.exp.node.call("sim/set_robot_pose", api().srv_types().SetRobotPose, timeout=20.0,
                                     x=x0, y=y0, theta=th0)
        if not r.success:
            raise RuntimeError(f"SimTwo: the teleport to the route's start failed: {r.message}")
        self.applied.append("the real SimTwo (raf simtwo run), teleported to the route's start")

    def drive(self, robot, settle_s: float = 0.0) -> None:
        """Drive the route on ground truth; then keep the robot stopped for ``settle_s`` simulation seconds
        (the filter's verdicts on the last fixes become final when they leave its history)."""
        self.rec = rec = Recorder(self.graph.exp, self.route, self.speed, robot, bag_path=self.bag)
        wall0 = time.monotonic()
        last_report = wall0
        while rec.done_t is None:
            self.procs.check()
            now = time.monotonic()
            if now - wall0 > self.args.timeout:
                self.notes.append(f"{self.name}: timeout after {self.args.timeout:.0f} wall s at "
                                  f"{100 * rec.pp.progress:.0f} % of the route")
                break
            if now - last_report > 15:
                last_report = now
                d = rec.arrays()
                ts = d["gt"][-1, 0] if len(d["gt"]) else 0.0
                print(f"  {self.name}: route {100 * rec.pp.progress:5.1f} %, sim time {ts:6.1f} s, "
                      f"{len(d['planar'])} planar fixes, {len(d['ekf'])} EKF poses", flush=True)
            time.sleep(0.2)
        for _ in range(10):  # stop the robot
            rec.cmd.publish(rec.Twist())
            time.sleep(0.05)
        if rec.done_t is not None and settle_s > 0:
            t_wait = time.monotonic()
            while rec.last_gt_t < rec.done_t + settle_s and time.monotonic() - t_wait < 60:
                self.procs.check()
                time.sleep(0.2)
        else:
            time.sleep(1.0)
        rec.close_bag()


@contextlib.contextmanager
def experiment_graph(node_name: str, work: Path, log_dir: Path):
    """A private ROS graph with this process's :class:`~robotatfactory.ros.processes.ExperimentNode` on it, as a
    :class:`Graph`. On the way out the node closes and the graph ends; the work folder goes when the body
    finished (its logs live in ``log_dir``), else where the logs are is printed."""
    from ..ros.master import private_graph
    from ..ros.processes import ExperimentNode

    private = private_graph().start()
    exp = None
    ok = False
    try:
        private.use_in_this_process()
        exp = ExperimentNode(node_name)
        yield Graph(private, exp)
        ok = True
    finally:
        if exp is not None:
            exp.close()
        private.cleanup()
        if ok:
            shutil.rmtree(work, ignore_errors=True)
        else:
            print(f"logs: {log_dir}", file=sys.stderr)


def calibration_drive(args, plan: Plan, graph: Graph, log_dir: Path, work: Path, robot_file: Path | None, robot,
                      out_dir: Path | None, notes: list, sim_extra: tuple[str, ...] = (),
                      constraints: CalibrationConstraints | None = None) -> tuple[Path | None, dict]:
    """``--calibration auto``: drive the calibration route recording a bag of camera/image_raw (a frame per
    IMAGE_PERIOD_S), camera_info and odom (``--save-bag FILE`` keeps it), then ``raf calibrate --bag`` on it; with
    ``--bag FILE``, no drive: ``raf calibrate`` on that recording. Returns the calibration file and result keys.
    ``sim_extra``: more ``raf sim`` options for the drive (the competition experiment's world: ``--round R
    --set perturb.NAME=VALUE``, so that the stand-in renders with the round's drawn camera). ``constraints``: what
    raf calibrate holds and its square-pixel prior (on SimTwo :data:`~..simtwo_linux.scene.SIMTWO_CALIBRATION`;
    None: raf calibrate's defaults, nothing held)."""
    from ..localization.route import make_route
    from ..ros.mw import bag_format

    out: dict = {}
    if plan.bag:
        bag = Path(plan.bag)
        out["calibration_bag"] = str(bag)
    else:
        # ~130 MB: deleted with the work directory unless --save-bag names where to keep it (the YAML is kept);
        # a ROS 1 bag is a file, a rosbag2 a directory
        bag_name = "calibration.bag" if bag_format(graph.middleware) == "bag" else "calibration_bag"
        bag = Path(args.save_bag) if args.save_bag else work / bag_name
        route = make_route("calibration", 1)
        with Session(args, plan, graph, log_dir, "calibration", route, robot_file, None, localize=False, bag=bag,
                     speed=args.calibration_speed, sim_extra=sim_extra) as ses:
            ses.start()
            ses.drive(robot)
            counts = dict(ses.rec.bag_counts)
            notes.extend(ses.notes)
        out.update({"calibration_bag_images": counts["images"], "calibration_bag_odom": counts["odom"]})
    calib = (out_dir or work) / "calibration.yaml"
    cmd = _raf("--field", args.field, "calibrate", "--bag", str(bag), "--out", str(calib),
               *(constraints.calibrate_args() if constraints else ()))
    t0 = time.monotonic()
    with open(log_dir / "calibrate.log", "wb") as log:
        r = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=graph.env(), timeout=1800)
    out["calibration_wall_s"] = time.monotonic() - t0
    if r.returncode != 0 or not calib.is_file():
        tail = (log_dir / "calibrate.log").read_text(errors="replace").splitlines()[-15:]
        raise RuntimeError(f"raf calibrate failed (exit {r.returncode}):\n" + "\n".join(tail))
    out["calibration_source"] = (f"raf calibrate on the recorded drive {bag} (--bag: replayed, not driven)"
                                 if plan.bag else "raf calibrate on the calibration drive")
    out.update(constraints.keys() if constraints else {"calibration_held": "none"})
    return calib, out
