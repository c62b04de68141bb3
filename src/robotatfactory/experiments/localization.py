"""``raf experiment localization``: the paper's second validation test, made quantitative, where it would run.

Runs on ROS 1 or ROS 2 (``raf --middleware ros2 experiment localization``), each in its own process against a
private graph (a roscore on a free port / a ROS 2 domain id of its own): the stand-in simulator (``raf sim``,
LIDAR beacons in the team areas), the bridge (``raf bridge``) and the localization (``raf localize`` with
every method computed). This process drives a route (:mod:`robotatfactory.localization.route`: the
``reference`` loop the localization was tuned on and the held-out ``second`` route, a figure-eight with
station visits) with a pure-pursuit controller on the GROUND-TRUTH pose (so that control does not depend on
what is measured), records ground truth, odometry, every camera fix, the filter's verdict on each fix and the
EKF, and prints position and heading errors (RMSE, 95th percentile, maximum) of odometry alone, the paper's
closest-marker method, the closest marker with the mount check, the all-marker PnP, the planar fit and the
EKF.

Two modes (every key and table carries the mode's name):

- ``simtwo`` (default): the stand-in as SimTwo behaves -- its defaults (camera frames not on a grid of
  simulation time, whole-sweep LIDAR updates with the robot's own wheels in the scan, SimTwo's speed
  controller), no lockstep (SimTwo cannot wait for a reply), the wheel calibration error, and the camera
  calibration from ``raf calibrate`` on a recording of a short calibration drive (``--calibration auto``; a ROS
  1 bag on ROS 1, a rosbag2 on ROS 2; ``--save-bag FILE`` keeps it, ``--bag FILE`` replays a recorded drive,
  of either format, instead of driving one) instead of the renderer's own values.
- ``ideal`` (``--ideal``): the idealisations the earlier figures were measured with, as far as ``raf sim``
  offers them (lockstep, camera on the render grid, per-ray LIDAR, no self-hits, the project's own speed
  controller) and the exact camera calibration.

With ``--out DIR``: per route a trajectory figure and an error-against-time figure, the TF tree (tf2_tools
view_frames, PDF and PNG; ROS 1), an RViz screenshot taken under Xvfb (ROS 1), the RViz configuration and the
processes' logs.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

NAME = "localization"
HELP = ("simulator + bridge + localization on two routes, SimTwo-like by default (--ideal for the idealised "
        "stand-in): errors of odometry, closest marker, all markers, planar fit, EKF")
MODES = ("simtwo", "ideal")
REAL = "real_simtwo"  # the mode (and keys' prefix) of --simulator simtwo: the real SimTwo, not the stand-in
ROUTE_CHOICES = ("reference", "second", "both")
DEFAULT_LAPS = {"reference": 2, "second": 1}
BAD_FIX_M = 0.05  # an accepted camera fix further than this from the truth is a failure
#: the targets (issue 9, item 5), per mode and route: key suffix -> target text
ROUTE_TARGETS = {
    "ekf_position_rmse_m": "<= 0.010",
    "ekf_heading_rmse_deg": "<= 1.0",
    "closest_over_ekf_position_rmse": ">= 3",
    "ekf_accepted_fixes_over_5cm": "== 0",
    "odometry_over_ekf_end_position_error": ">= 10 (informative)",
}
TARGETS = {f"{m}_{r}_{k}": v for m in (*MODES, REAL) for r in ("reference", "second") for k, v in ROUTE_TARGETS.items()}
#: raf experiment exits with status 1 when one of the *_target_met keys is false
EXIT_STATUS_FROM_TARGETS = True
METHODS = ("closest", "closest_checked", "all_pnp", "planar")
LABELS = {"odometry": "odometry alone", "closest": "closest marker (paper)", "closest_checked":
          "closest marker + mount check", "all_pnp": "all-marker PnP", "planar": "planar fit (mount fixed)",
          "ekf": "EKF (odometry + planar fixes + beacons)"}

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


def add_arguments(parser) -> None:
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--mode", choices=MODES, default="simtwo",
                      help="simtwo: the stand-in as SimTwo behaves, calibration from raf calibrate (default); "
                           "ideal: the idealised stand-in and the exact calibration (the earlier figures)")
    mode.add_argument("--ideal", dest="mode", action="store_const", const="ideal", help="same as --mode ideal")
    parser.add_argument("--simulator", choices=("standin", "simtwo"), default="standin",
                        help="standin: raf sim (default); simtwo: the real SimTwo (raf simtwo run, camera open, field "
                             "simtwo2022, its own wheels: no --wheel-error, no beacons), the robot teleported to each "
                             "route's start; keys start with " + REAL)
    parser.add_argument("--route", choices=ROUTE_CHOICES, default="both",
                        help="reference: the loop the localization was tuned on; second: the held-out "
                             "figure-eight with station visits; both (default), one after the other")
    parser.add_argument("--laps", type=int, default=None,
                        help="laps of each route (default: 2 of the reference loop, 1 of the second route)")
    parser.add_argument("--speed", type=float, default=0.2,
                        help="cruise speed, m/s (default 0.2; the second route drives 0.6-1.25x of it)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (sensor noise, parts)")
    parser.add_argument("--no-beacons", action="store_true", help="no LIDAR beacons in the team areas")
    parser.add_argument("--wheel-error", "--calibration-error", dest="wheel_error", default="0.01,-0.005",
                        metavar="TRACK,RADIUS",
                        help="relative errors of the robot's nominal wheel geometry (what the bridge's odometry and "
                             "the filter use) against the simulated robot: the simulated track is (1 + TRACK) and "
                             "the wheel radius (1 + RADIUS) times the nominal ones (default 0.01,-0.005: a robot "
                             "calibrated to 1 %% and 0.5 %%; 0,0 for the nominal robot, whose odometry in the "
                             "stand-in simulator is almost perfect)")
    parser.add_argument("--calibration", default=None, metavar="FILE|auto|true|none",
                        help="camera calibration given to the bridge and the localization: auto = drive a short "
                             "calibration route recording camera/image_raw and odom in a rosbag and run raf "
                             "calibrate on it (default in the simtwo mode); true = the stand-in's true camera "
                             "(default in the ideal mode with --camera-error); none = the robot file's nominal "
                             "values (default in the ideal mode); or a calibration YAML file")
    parser.add_argument("--camera-error", action="store_true",
                        help="render with a camera that differs from the nominal one (fx and fy +3 %%, cx +4 px, "
                             "cy -3 px, pitch +1 degree), as a user's SimTwo may")
    parser.add_argument("--bag", metavar="FILE", default=None,
                        help="replay a recorded calibration drive (a ROS 1 bag or a rosbag2, e.g. from --save-bag or "
                             "raf record) instead of driving it: raf calibrate runs on it (implies --calibration "
                             "auto; the results say so)")
    parser.add_argument("--save-bag", metavar="FILE", default=None,
                        help="keep the calibration drive's recording there (ROS 1: a .bag file; ROS 2: a rosbag2 "
                             "directory), to replay with --bag")
    parser.add_argument("--calibration-speed", type=float, default=0.15,
                        help="cruise speed of the calibration drive, m/s (default 0.15)")
    parser.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                        help="a localization setting for the node, e.g. node/use_lidar=false (repeatable)")
    parser.add_argument("--timeout", type=float, default=900.0,
                        help="wall seconds for each drive (default 900)")
    parser.add_argument("--no-rviz", action="store_true", help="skip the RViz screenshot")
    parser.add_argument("--no-tf-tree", action="store_true", help="skip the TF tree")


@dataclass(frozen=True)
class Plan:
    """What one run of the experiment does (parsed and checked options)."""

    mode: str
    routes: tuple[tuple[str, int], ...]  # (route name, laps)
    calibration: str  # auto | true | none | a file path
    camera_error: bool
    track_error: float
    radius_error: float
    speed: float
    bag: str | None = None  # a recorded calibration drive to replay (--bag) instead of driving one

    @property
    def prefix(self) -> str:
        return self.mode


def plan_from_args(args) -> Plan:
    """Check the options and resolve the mode's defaults; ConfigError names the bad option."""
    from ..errors import ConfigError

    mode = getattr(args, "mode", "simtwo") or "simtwo"
    if mode not in MODES:
        raise ConfigError(f"--mode {mode!r}: choose one of {', '.join(MODES)}")
    if getattr(args, "simulator", "standin") == "simtwo":
        if mode != "simtwo" or args.camera_error:
            raise ConfigError("--simulator simtwo: the real SimTwo has neither --ideal nor --camera-error (its camera "
                              "is what it renders)")
        mode = REAL
    if args.laps is not None and args.laps < 1:
        raise ConfigError("--laps must be >= 1")
    if not 0.02 <= args.speed <= 0.5:
        raise ConfigError("--speed must be in 0.02..0.5 m/s")
    names = ("reference", "second") if args.route == "both" else (args.route,)
    if any(n not in DEFAULT_LAPS for n in names):
        raise ConfigError(f"--route {args.route!r}: choose one of {', '.join(ROUTE_CHOICES)}")
    routes = tuple((n, args.laps if args.laps is not None else DEFAULT_LAPS[n]) for n in names)
    try:
        track_err, radius_err = (float(v) for v in str(args.wheel_error).split(","))
    except ValueError:
        raise ConfigError(f"--wheel-error {args.wheel_error!r}: expected TRACK,RADIUS, e.g. 0.01,-0.005") from None
    if not (abs(track_err) < 0.2 and abs(radius_err) < 0.2):
        raise ConfigError("--wheel-error: each relative error must be within +-0.2")
    cal = args.calibration
    bag = getattr(args, "bag", None)
    if bag:
        if not Path(bag).exists():
            raise ConfigError(f"--bag {bag!r}: no such bag file or rosbag2 directory")
        if cal not in (None, "auto"):
            raise ConfigError("--bag replays the calibration drive for --calibration auto: leave --calibration out")
        if getattr(args, "save_bag", None):
            raise ConfigError("--bag replays a recording; --save-bag keeps a new one: use one of them")
    if getattr(args, "save_bag", None) and Path(args.save_bag).exists():
        raise ConfigError(f"--save-bag {args.save_bag!r} exists already: give a new name (a bag is never overwritten)")
        cal, bag = "auto", str(Path(bag).resolve())
    if cal is None:
        cal = "auto" if mode in ("simtwo", REAL) else ("true" if args.camera_error else "none")
    if cal not in ("auto", "true", "none"):
        if not Path(cal).is_file():
            raise ConfigError(f"--calibration {cal!r}: not a file (or auto, true, none)")
        cal = str(Path(cal).resolve())
    if mode == REAL:
        if cal == "true":
            raise ConfigError("--calibration true: the stand-in's true camera; on SimTwo use auto, none or a file")
        track_err = radius_err = 0.0  # SimTwo's wheels are what its scene builds
    return Plan(mode, routes, cal, bool(args.camera_error), track_err, radius_err, float(args.speed), bag or None)


# ------------------------------------------------------------------------------------------- recording


class Recorder:
    """The experiment's recording on this process's node (:class:`~robotatfactory.ros.processes.ExperimentNode`,
    either middleware): drives the route on ground truth and records every pose stream; on the calibration
    drive also camera/image_raw (every ``image_every``-th frame), camera_info and odom into a bag
    (:func:`open_bag_writer`)."""

    def __init__(self, exp, route, speed: float, robot, bag_path: Path | None = None, image_every: int = 3):
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
        # the calibration drive: camera/image_raw (every image_every-th frame), camera_info and odom to a bag
        self.bag = None
        if bag_path is not None:
            from sensor_msgs.msg import CameraInfo, Image

            self.bag = bag = BagSink(bag_path, image_every)
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
        for st in msg.status:
            if "raf_localization" in st.name:
                with self.lock:
                    self.diag.update({kv.key: kv.value for kv in st.values})

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
    under global topic names (``/camera/image_raw``), stamped with their header stamps; images only every
    ``image_every``-th. ``counts``: messages written (images, odom, camera_info)."""

    def __init__(self, path: Path, image_every: int = 3):
        self._bag = open_bag_writer(path)
        self._lock = threading.Lock()
        self._every, self._n = max(1, int(image_every)), 0
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
        with self._lock:
            self._n += 1
            take = (self._n - 1) % self._every == 0
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


# ------------------------------------------------------------------------------------------- analysis


def analyse(d: dict, done_t: float | None) -> tuple[dict, dict]:
    """Per-method error series and the flat result dict."""
    from ..localization.metrics import errors, odometry_in_map, path_length, stats

    gt = d["gt"]
    t_gt, P_gt = gt[:, 0], gt[:, 1:4]
    t_end = done_t if done_t is not None else t_gt[-1]
    keep = t_gt <= t_end + 1e-9
    t_gt, P_gt = t_gt[keep], P_gt[keep]
    series = {}
    odo = d["odom"]
    odo = odo[odo[:, 0] <= t_end + 1e-9]
    if len(odo):
        from ..localization.metrics import interpolate

        start = interpolate(odo[:1, 0], t_gt, P_gt)[0]
        series["odometry"] = (odo[:, 0], odometry_in_map(odo[:, 1:4], tuple(start)))
    for m in ("ekf", *METHODS):
        a = d[m]
        if len(a):
            a = a[a[:, 0] <= t_end + 1e-9]
            series[m] = (a[:, 0], a[:, 1:4])
    out = {"route_duration_sim_s": float(t_gt[-1] - t_gt[0]), "route_length_m": path_length(P_gt),
           "route_completed": done_t is not None}
    errs = {}
    for m, (t, P) in series.items():
        te, ep, eh = errors(t, P, t_gt, P_gt)
        errs[m] = (te, ep, eh)
        sp, sh = stats(ep), stats(eh)
        out[f"{m}_samples"] = sp["n"]
        out[f"{m}_position_rmse_m"] = sp["rmse"]
        out[f"{m}_position_p95_m"] = sp["p95"]
        out[f"{m}_position_max_m"] = sp["max"]
        out[f"{m}_heading_rmse_deg"] = math.degrees(sh["rmse"]) if sh["n"] else math.nan
        out[f"{m}_heading_p95_deg"] = math.degrees(sh["p95"]) if sh["n"] else math.nan
        out[f"{m}_heading_max_deg"] = math.degrees(sh["max"]) if sh["n"] else math.nan
    # at the end of the route: mean error over the last second
    for m in ("odometry", "ekf"):
        if m in errs and len(errs[m][0]):
            te, ep, eh = errs[m]
            last = te >= te[-1] - 1.0
            out[f"{m}_end_position_error_m"] = float(np.mean(ep[last]))
            out[f"{m}_end_heading_error_deg"] = math.degrees(float(np.mean(eh[last])))
    if "ekf" in errs:
        # consistency of the EKF's covariance: mean normalised error squared over the drive (3 expected)
        a = d["ekf"]
        a = a[a[:, 0] <= t_end + 1e-9]
        from ..localization.geometry import wrap_angle
        from ..localization.metrics import interpolate

        ref = interpolate(a[:, 0], t_gt, P_gt)
        ok = np.all(np.isfinite(ref), axis=1)
        dd = a[ok, 1:4] - ref[ok]
        dd[:, 2] = wrap_angle(dd[:, 2])
        var = a[ok, 4:7]
        out["ekf_nees_diag_mean"] = float(np.mean(np.sum(dd ** 2 / np.maximum(var, 1e-18), axis=1)))
    # the filter's final verdict on each camera fix: accepted fixes far from the truth are failures
    for key in ("accepted", "rejected"):
        a = d.get(key, np.zeros((0, 4)))
        a = a[a[:, 0] <= t_end + 1e-9] if len(a) else a
        n, n_bad, emax = 0, 0, math.nan
        if len(a):
            te, ep, eh = errors(a[:, 0], a[:, 1:4], t_gt, P_gt)
            n, n_bad = len(ep), int(np.sum(ep > BAD_FIX_M))
            emax = float(np.max(ep)) if len(ep) else math.nan
            if key == "accepted":
                errs["accepted"] = (te, ep, eh)
        out[f"ekf_{key}_fixes"] = n
        out[f"ekf_{key}_fixes_over_5cm"] = n_bad
        out[f"ekf_{key}_fix_error_max_m"] = emax
    ekf_rmse = out.get("ekf_position_rmse_m", math.nan)
    out["closest_over_ekf_position_rmse"] = out.get("closest_position_rmse_m", math.nan) / ekf_rmse
    out["odometry_over_ekf_end_position_error"] = (out.get("odometry_end_position_error_m", math.nan)
                                                   / max(out.get("ekf_end_position_error_m", math.nan), 1e-6))
    out["ekf_position_rmse_target_met"] = bool(ekf_rmse <= 0.010)
    out["ekf_heading_rmse_target_met"] = bool(out.get("ekf_heading_rmse_deg", math.inf) <= 1.0)
    out["ekf_3x_closest_target_met"] = bool(out["closest_over_ekf_position_rmse"] >= 3)
    out["ekf_no_bad_fix_accepted_target_met"] = bool(out["ekf_accepted_fixes"] > 0
                                                     and out["ekf_accepted_fixes_over_5cm"] == 0)
    out["ekf_10x_odometry_end_met"] = bool(out["odometry_over_ekf_end_position_error"] >= 10)
    return errs, out


def table(out: dict, title: str = "") -> str:
    rows = [title] if title else []
    rows += ["| method | samples | position RMSE / p95 / max (cm) | heading RMSE / p95 / max (deg) |",
             "|---|---|---|---|"]
    for m in ("odometry", *METHODS, "ekf"):
        if f"{m}_samples" not in out:
            continue
        g = lambda k: out.get(f"{m}_{k}", math.nan)  # noqa: E731
        rows.append(f"| {LABELS[m]} | {out[f'{m}_samples']} | {100 * g('position_rmse_m'):.2f} / "
                    f"{100 * g('position_p95_m'):.2f} / {100 * g('position_max_m'):.2f} | "
                    f"{g('heading_rmse_deg'):.2f} / {g('heading_p95_deg'):.2f} / {g('heading_max_deg'):.2f} |")
    if "ekf_accepted_fixes" in out:
        rows.append(f"\ncamera fixes accepted by the filter: {out['ekf_accepted_fixes']} (over 5 cm off: "
                    f"{out['ekf_accepted_fixes_over_5cm']}, worst {100 * out['ekf_accepted_fix_error_max_m']:.2f} cm); "
                    f"rejected: {out['ekf_rejected_fixes']} ({out['ekf_rejected_fixes_over_5cm']} over 5 cm off)")
    return "\n".join(rows)


# ------------------------------------------------------------------------------------------- figures


def figures(d: dict, errs: dict, field, route_pts, out_dir: Path, t_end: float | None, prefix: str = "localization",
            title: str = "") -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..field.draw import draw_field
    from ..localization.metrics import odometry_in_map, interpolate

    gt = d["gt"]
    if t_end is not None:
        gt = gt[gt[:, 0] <= t_end + 1e-9]
    fig, ax = plt.subplots(figsize=(11, 8))
    draw_field(field, ax)
    ax.plot(route_pts[:, 0], route_pts[:, 1], ":", color="0.6", lw=1, label="route (waypoints)")
    ax.plot(gt[:, 1], gt[:, 2], "k-", lw=2, label="ground truth")
    if len(d["odom"]):
        odo = d["odom"] if t_end is None else d["odom"][d["odom"][:, 0] <= t_end + 1e-9]
        start = interpolate(odo[:1, 0], gt[:, 0], gt[:, 1:4])[0]
        om = odometry_in_map(odo[:, 1:4], tuple(start))
        ax.plot(om[:, 0], om[:, 1], "-", color="tab:orange", lw=1.2, label="odometry alone")
    c = d["closest"]
    if len(c):
        ax.plot(c[:, 1], c[:, 2], ".", color="tab:red", ms=3, alpha=0.6, label="closest marker (paper)")
    p = d["planar"]
    if len(p):
        ax.plot(p[:, 1], p[:, 2], ".", color="tab:green", ms=2, alpha=0.6, label="planar fit")
    e = d["ekf"]
    if len(e):
        e = e if t_end is None else e[e[:, 0] <= t_end + 1e-9]
        ax.plot(e[:, 1], e[:, 2], "-", color="tab:blue", lw=1, label="EKF")
    ax.set_xlim(field.floor.x[0] - 0.12, field.floor.x[1] + 0.12)
    ax.set_ylim(field.floor.y[0] - 0.12, field.floor.y[1] + 0.12)
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    ax.set_title(f"raf experiment localization: trajectories in map {title}")
    fig.tight_layout()
    fig.savefig(out_dir / f"{prefix}_trajectory.png", dpi=110)
    plt.close(fig)

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(11, 7), sharex=True)
    t0 = gt[0, 0]
    styles = {"odometry": ("tab:orange", "-", None), "closest": ("tab:red", "", "."),
              "all_pnp": ("tab:purple", "", "."), "planar": ("tab:green", "", "."), "ekf": ("tab:blue", "-", None)}
    for m, (col, ls, mk) in styles.items():
        if m not in errs or not len(errs[m][0]):
            continue
        te, ep, eh = errs[m]
        kw = dict(color=col, linestyle=ls or "none", marker=mk, ms=2, lw=1, label=LABELS[m])
        a1.semilogy(te - t0, np.maximum(ep * 100, 1e-3), **kw)
        a2.semilogy(te - t0, np.maximum(np.degrees(eh), 1e-3), **kw)
    a1.axhline(1.0, color="k", lw=0.6, ls="--")
    a2.axhline(1.0, color="k", lw=0.6, ls="--")
    a1.set_ylabel("position error (cm)")
    a2.set_ylabel("heading error (deg)")
    a2.set_xlabel("simulation time (s)")
    a1.legend(fontsize=8, ncol=3)
    a1.set_title(f"errors against ground truth {title} (dashed: the 1 cm / 1 deg targets of the EKF)")
    fig.tight_layout()
    fig.savefig(out_dir / f"{prefix}_errors.png", dpi=110)
    plt.close(fig)


RVIZ = """Panels:
  - Class: rviz/Displays
    Name: Displays
Visualization Manager:
  Class: ""
  Displays:
    - Class: rviz/Grid
      Name: Grid
      Enabled: true
      Cell Size: 0.1
      Plane Cell Count: 20
      Reference Frame: map
      Color: 160; 160; 164
    - Class: rviz/MarkerArray
      Name: Field markers
      Enabled: true
      Marker Topic: /field/markers
    - Class: rviz/TF
      Name: TF
      Enabled: true
      Show Names: true
      Show Axes: true
      Show Arrows: true
      Marker Scale: 0.25
      Frame Timeout: 15
      Frames:
        All Enabled: true
    - Class: rviz/MarkerArray
      Name: Detected markers
      Enabled: true
      Marker Topic: /aruco/markers
    - Class: rviz/PoseWithCovariance
      Name: EKF pose
      Enabled: true
      Topic: /pose
      Shape: Arrow
      Color: 0; 120; 255
      Shaft Length: 0.12
      Shaft Radius: 0.01
      Head Length: 0.04
      Head Radius: 0.025
    - Class: rviz/PoseWithCovariance
      Name: Camera pose (closest marker)
      Enabled: true
      Topic: /camera_pose
      Shape: Axes
      Axes Length: 0.08
      Axes Radius: 0.006
    - Class: rviz/LaserScan
      Name: LIDAR
      Enabled: true
      Topic: /scan
      Size (m): 0.01
      Color Transformer: FlatColor
      Color: 255; 0; 0
    - Class: rviz/Image
      Name: Debug image
      Enabled: true
      Image Topic: /aruco/debug_image
  Enabled: true
  Global Options:
    Fixed Frame: map
    Background Color: 40; 40; 40
    Frame Rate: 15
  Views:
    Current:
      Class: rviz/Orbit
      Distance: 1.0
      Focal Point:
        X: 0.0
        Y: -0.15
        Z: 0.0
      Pitch: 0.6
      Yaw: 4.71
      Target Frame: map
Window Geometry:
  Width: 1600
  Height: 1000
  X: 0
  Y: 0
  Displays:
    collapsed: false
  Debug image:
    collapsed: false
"""


def save_debug_image(exp, path: Path, notes: list) -> None:
    """One aruco/debug_image frame (the paper's figure 6) as PNG."""
    from sensor_msgs.msg import Image

    from ..ros.mw import QoS

    try:
        msg = exp.wait_for_message("aruco/debug_image", Image, timeout=10.0, qos=QoS.SENSOR)
        if msg is None:
            raise TimeoutError("no aruco/debug_image in 10 s")
        import cv2

        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, 3)
        cv2.imwrite(str(path), img)
    except Exception as ex:  # noqa: BLE001 - a figure, not the measurement
        notes.append(f"debug image: {type(ex).__name__}: {ex}")


def _free_display() -> int:
    for n in range(91, 200):
        if not os.path.exists(f"/tmp/.X{n}-lock") and not os.path.exists(f"/tmp/.X11-unix/X{n}"):
            return n
    raise RuntimeError("no free X display number")


def rviz_screenshot(env: dict, cfg: Path, png: Path, log_dir: Path, wait: float = 20.0, attempts: int = 3) -> str:
    """RViz under Xvfb, then xwd of the root window converted to PNG; RViz with software OpenGL sometimes
    aborts at start-up, so it gets a few attempts. Returns '' or what went wrong."""
    why = ""
    for i in range(attempts):
        why = _rviz_once(env, cfg, png, log_dir, wait)
        if not why:
            return ""
    return f"{why} (after {attempts} attempts)"


def _rviz_once(env: dict, cfg: Path, png: Path, log_dir: Path, wait: float) -> str:
    from ..ros.master import stop_process

    for tool in ("Xvfb", "rviz", "xwd"):
        if shutil.which(tool) is None:
            return f"{tool} not installed"
    disp = _free_display()
    xlog = open(log_dir / "xvfb.log", "wb")
    xvfb = subprocess.Popen(["Xvfb", f":{disp}", "-screen", "0", "1600x1000x24", "-nolisten", "tcp"],
                            stdout=xlog, stderr=subprocess.STDOUT, start_new_session=True)
    rv = None
    try:
        time.sleep(1.5)
        e = dict(env, DISPLAY=f":{disp}", LIBGL_ALWAYS_SOFTWARE="1")
        rlog = open(log_dir / "rviz.log", "wb")
        rv = subprocess.Popen(["rviz", "-d", str(cfg)], env=e, stdout=rlog, stderr=subprocess.STDOUT,
                              start_new_session=True)
        time.sleep(wait)
        if rv.poll() is not None:
            return f"rviz exited with code {rv.returncode} (see rviz.log)"
        xwd = png.with_suffix(".xwd")
        subprocess.run(["xwd", "-root", "-silent", "-display", f":{disp}", "-out", str(xwd)], check=True,
                       timeout=30)
        img = read_xwd(xwd)
        import cv2

        cv2.imwrite(str(png), img)
        xwd.unlink()
        return ""
    except Exception as ex:  # noqa: BLE001 - a figure, not the measurement
        return f"{type(ex).__name__}: {ex}"
    finally:
        if rv is not None:
            stop_process(rv)
        stop_process(xvfb)


def read_xwd(path: Path) -> np.ndarray:
    """An X window dump (ZPixmap, 24/32 bits per pixel, as xwd writes from a 24-bit Xvfb) to BGR."""
    b = path.read_bytes()
    h = np.frombuffer(b[:100], dtype=">u4")
    header_size, fmt, depth, width, height = int(h[0]), int(h[2]), int(h[3]), int(h[4]), int(h[5])
    bpp, bpl, ncolors = int(h[11]), int(h[12]), int(h[19])
    byte_order = int(h[7])
    if fmt != 2 or bpp not in (24, 32):
        raise ValueError(f"unsupported xwd: format {fmt}, {bpp} bits per pixel, depth {depth}")
    off = header_size + ncolors * 12
    data = np.frombuffer(b[off:off + bpl * height], dtype=np.uint8).reshape(height, bpl)
    px = data[:, :width * bpp // 8].reshape(height, width, bpp // 8)
    if byte_order == 0:  # LSBFirst: B G R (X)
        return np.ascontiguousarray(px[:, :, :3])
    return np.ascontiguousarray(px[:, :, 1:4][:, :, ::-1] if bpp == 32 else px[:, :, ::-1])


def tf_tree(env: dict, out_dir: Path, log_dir: Path) -> str:
    script = "/usr/lib/tf2_tools/view_frames.py"
    if not os.path.exists(script):
        exe = shutil.which("view_frames")
        if exe is None:
            return "tf2_tools view_frames not found"
        cmd = [exe]
    else:
        cmd = [sys.executable, script]
    try:
        with open(log_dir / "view_frames.log", "wb") as log:
            subprocess.run(cmd, env=env, cwd=out_dir, stdout=log, stderr=subprocess.STDOUT, timeout=120, check=True)
        if shutil.which("dot") and (out_dir / "frames.gv").exists():
            subprocess.run(["dot", "-Tpng", "-Gdpi=70", "frames.gv", "-o", "frames.png"], cwd=out_dir, timeout=60,
                           check=True)
        return "" if (out_dir / "frames.pdf").exists() else "view_frames wrote no frames.pdf"
    except Exception as ex:  # noqa: BLE001
        return f"{type(ex).__name__}: {ex}"


# ------------------------------------------------------------------------------------------- run


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
                 speed: float | None = None):
        from ..ros.processes import Procs

        self.args, self.plan, self.graph, self.name, self.route = args, plan, graph, name, route
        self.log_dir = log_dir / name
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs = Procs(self.log_dir, watch=("sim", "bridge", "localize"))
        self.robot_file, self.calibration_file, self.localize, self.bag = robot_file, calibration_file, localize, bag
        self.speed = speed if speed is not None else plan.speed
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
        if self.plan.mode == REAL:
            self._start_simtwo(bport, sport, cport)
        if self.localize:
            loc_args = ["--field", args.field, "localize", "--set", "node/all_methods=true",
                        *self._calibration_args()]
            for s_ in args.set:
                loc_args += ["--set", s_]
            self.procs.start("localize", _raf(*loc_args), env)
        if self.plan.mode == REAL:
            return
        time.sleep(3.0)  # let the bridge bind its port before the simulator starts sending
        x0, y0, th0 = self.route.start
        sim_args = ["--field", args.field, "sim", "--port", str(sport), "--bridge", f"127.0.0.1:{bport}",
                    "--camera-bind", cam, "--no-server", f"--start-pose={x0},{y0},{th0}", "--seed", str(args.seed),
                    "--status-every", "5", *self._sim_mode_args()]
        if not args.no_beacons:
            sim_args.append("--beacons")
        sim_args.append("--no-control")  # SimTwo has no control channel; nor a port clash here
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
                      out_dir: Path | None, notes: list) -> tuple[Path | None, dict]:
    """``--calibration auto``: drive the calibration route recording a bag of camera/image_raw (every 3rd
    frame), camera_info and odom (``--save-bag FILE`` keeps it), then ``raf calibrate --bag`` on it; with
    ``--bag FILE``, no drive: ``raf calibrate`` on that recording. Returns the calibration file and result keys."""
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
                     speed=args.calibration_speed) as ses:
            ses.start()
            ses.drive(robot)
            counts = dict(ses.rec.bag_counts)
            notes.extend(ses.notes)
        out.update({"calibration_bag_images": counts["images"], "calibration_bag_odom": counts["odom"]})
    calib = (out_dir or work) / "calibration.yaml"
    cmd = _raf("--field", args.field, "calibrate", "--bag", str(bag), "--out", str(calib))
    t0 = time.monotonic()
    with open(log_dir / "calibrate.log", "wb") as log:
        r = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, env=graph.env(), timeout=1800)
    out["calibration_wall_s"] = time.monotonic() - t0
    if r.returncode != 0 or not calib.is_file():
        tail = (log_dir / "calibrate.log").read_text(errors="replace").splitlines()[-15:]
        raise RuntimeError(f"raf calibrate failed (exit {r.returncode}):\n" + "\n".join(tail))
    out["calibration_source"] = (f"raf calibrate on the recorded drive {bag} (--bag: replayed, not driven)"
                                 if plan.bag else "raf calibrate on the calibration drive")
    return calib, out


def calibration_keys(calib: Path | None, true_camera) -> dict:
    """The calibration's values and their errors against the stand-in's true camera."""
    if calib is None:
        return {}
    from ..localization.calibration import compare, load_calibration

    c = load_calibration(calib).apply(true_camera)
    out = {f"calibration_{k}": float(getattr(c, k)) for k in ("fx", "fy", "cx", "cy", "pitch_down_deg")}
    out.update({f"calibration_{k}": float(v) for k, v in compare(c, true_camera).items()})
    return out


def run_route(args, plan: Plan, graph: Graph, log_dir: Path, work: Path, name: str, laps: int, robot_file, robot,
              nominal_robot, calib: Path | None, field, out_dir: Path | None, notes: list) -> dict:
    """One route: start the processes, drive, analyse; returns the route's keys, unprefixed."""
    from ..localization.config import load_config
    from ..localization.route import make_route

    route = make_route(name, laps)
    with Session(args, plan, graph, log_dir, name, route, robot_file, calib) as ses:
        ses.start()
        ses.drive(nominal_robot, settle_s=load_config().ekf.history_s + 1.0)
        data = ses.rec.arrays()
        done_t = ses.rec.done_t
        with ses.rec.lock:
            diag = dict(ses.rec.diag)
        notes.extend(ses.notes)
        if out_dir is not None and name == plan.routes[0][0]:
            _pictures(args, graph, data, out_dir, log_dir, notes)
        applied = list(ses.applied)
    if len(data["gt"]) < 10:
        raise RuntimeError(f"{name}: no ground truth recorded: did the simulator and the bridge run? "
                           f"(logs in {log_dir})")
    errs, out = analyse(data, done_t)
    out = {"laps": laps, **out}
    title = f"mode {plan.mode}, route {name} ({laps} lap{'s' if laps > 1 else ''})"
    print(table(out, f"\n{title}:"))
    if out_dir is not None:
        prefix = "localization" if name == "reference" else f"localization_{name}"
        if plan.mode != "simtwo":
            prefix += f"_{plan.mode}"
        figures(data, errs, field, route.points, out_dir, done_t, prefix, f"({title})")
        (out_dir / f"{prefix}_table.md").write_text(table(out, f"{title}:") + "\n")
        np.savez_compressed(out_dir / f"{prefix}_data.npz", **{k: v for k, v in data.items()})
    for k in sorted(diag):  # the node's counters at the end: frames, fixes, rejections by reason, filter
        if k.startswith(("rejected_", "filter_", "scan_")) or k in ("frames", "fixes", "beacons_seen", "beacons_used",
                                                                    "frame_ms_median", "scans"):
            try:
                out[f"node_{k.replace(':', '_')}"] = float(diag[k]) if "." in diag[k] else int(diag[k])
            except ValueError:
                pass
    out["mode_options"] = " ".join(applied) or "(raf sim and raf bridge defaults)"
    return out


def _pictures(args, graph: Graph, data: dict, out_dir: Path, log_dir: Path, notes: list) -> None:
    """The debug image, the TF tree and the RViz screenshot (ROS 1's tools), while the processes still run."""
    env = graph.env()
    save_debug_image(graph.exp, out_dir / "localization_debug_image.png", notes)
    cfg = out_dir / "localization.rviz"
    # look over the robot's shoulder at what its camera sees (the paper's figure 7)
    x, y, th = data["gt"][-1, 1:4] if len(data["gt"]) else (0.0, 0.0, 0.0)
    fx, fy = x + 0.25 * math.cos(th), y + 0.25 * math.sin(th)
    view = RVIZ.replace("X: 0.0\n        Y: -0.15", f"X: {fx:.3f}\n        Y: {fy:.3f}")
    view = view.replace("Yaw: 4.71", f"Yaw: {(th + math.pi) % (2 * math.pi):.3f}")
    cfg.write_text(view)
    if graph.middleware != "ros1":
        notes.append("TF tree and RViz screenshot: ROS 1's view_frames and rviz; not made on ROS 2 (no tf2_tools "
                     "or rviz2 wheels)")
        return
    if not args.no_tf_tree:
        why = tf_tree(env, out_dir, log_dir)
        if why:
            notes.append(f"TF tree: {why}")
    if not args.no_rviz:
        why = rviz_screenshot(env, cfg, out_dir / "localization_rviz.png", log_dir)
        if why:
            notes.append(f"RViz screenshot: {why}")


def run(args, out_dir: Path | None) -> dict:
    from ..field import load_field
    from ..localization.calibration import write_calibration
    from ..robot import load_robot

    plan = plan_from_args(args)
    if plan.mode == REAL:  # SimTwo's scene is not the rules' field
        from ..simtwo_linux.scene import field_for_simtwo

        args.field = field_for_simtwo(args.field)
        args.no_beacons = True  # SimTwo's scene has no LIDAR beacons
    field = load_field(args.field)
    nominal = load_robot()
    work = Path(tempfile.mkdtemp(prefix="raf-exp-loc-"))
    log_dir = (out_dir / "logs") if out_dir else work / "logs"
    log_dir.mkdir(parents=True, exist_ok=True)
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
    robot, robot_file = sim_robot(plan, work)
    m = plan.mode
    out: dict = {"mode": m, "routes": " ".join(f"{n}x{k}" for n, k in plan.routes), "speed_m_per_s": plan.speed,
                 "controller": "pure pursuit on ground truth", "beacons": not args.no_beacons,
                 "sim_track_error_fraction": plan.track_error, "sim_wheel_radius_error_fraction": plan.radius_error,
                 "camera_error": plan.camera_error}
    notes: list[str] = []
    with experiment_graph("raf_experiment_localization", work, log_dir) as graph:
        out["middleware"] = graph.middleware
        calib: Path | None = None
        if plan.calibration == "auto":
            calib, keys = calibration_drive(args, plan, graph, log_dir, work, robot_file, nominal, out_dir, notes)
            out.update({f"{m}_{k}": v for k, v in keys.items()})
        elif plan.calibration == "true":
            calib = write_calibration((out_dir or work) / "calibration_true.yaml", robot.camera,
                                      {"source": "the stand-in's true camera (raf experiment localization)"})
            out[f"{m}_calibration_source"] = "the stand-in's true camera"
        elif plan.calibration == "none":
            out[f"{m}_calibration_source"] = "none (the robot file's nominal camera)"
        else:
            calib = Path(plan.calibration)
            out[f"{m}_calibration_source"] = f"file {calib}"
        out.update({f"{m}_{k}": v for k, v in calibration_keys(calib, robot.camera).items()})
        for name, laps in plan.routes:
            keys = run_route(args, plan, graph, log_dir, work, name, laps, robot_file, robot, nominal, calib,
                             field, out_dir, notes)
            out.update({f"{m}_{name}_{k}": v for k, v in keys.items()})
    failed = [k for k, v in out.items() if k.endswith("_target_met") and v is False]
    out["targets_met"] = not failed
    out["notes"] = "; ".join(notes)
    for n in notes:
        print(f"note: {n}")
    return out
