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

This module is the experiment: its options, the :class:`Plan` they resolve to, the targets, and the run (the
camera calibration, then per route :func:`run_route`: drive, analyse, draw). The rest is cut along its seams:

- :mod:`._localization_record`: the recording -- the private graph, the :class:`Session` (simulator, bridge,
  localization, recorder), the drive on ground truth, the calibration drive's bag and ``raf calibrate``;
- :mod:`._localization_views`: the pictures of the running graph (debug image, RViz screenshot, TF tree);
- :mod:`._localization_analysis`: the recorded arrays and the truth turned into the figures and the flat
  results (no ROS, no matplotlib);
- :mod:`._localization_figures`: the matplotlib figures (no ROS).
"""
from __future__ import annotations

import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ._localization_analysis import analyse, calibration_keys, table
from ._localization_figures import figures
from ._localization_record import Graph, Session, calibration_drive, experiment_graph, sim_robot
from ._localization_views import pictures

NAME = "localization"
HELP = ("simulator + bridge + localization on two routes, SimTwo-like by default (--ideal for the idealised "
        "stand-in): errors of odometry, closest marker, all markers, planar fit, EKF")
MODES = ("simtwo", "ideal")
REAL = "real_simtwo"  # the mode (and keys' prefix) of --simulator simtwo: the real SimTwo, not the stand-in
ROUTE_CHOICES = ("reference", "second", "both")
DEFAULT_LAPS = {"reference": 2, "second": 1}
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
    parser.add_argument("--calibrate-as", choices=("auto", "simtwo", "free"), default="auto",
                        help="with --calibration auto, what raf calibrate holds: simtwo = the principal point and "
                             "square pixels, as GLScene renders them (simtwo_linux.scene.SIMTWO_CALIBRATION); free = "
                             "nothing held, raf calibrate's defaults; auto (default) = simtwo on the real SimTwo, "
                             "free on the stand-in (raf experiment compare: simtwo on both, like for like)")
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

    @property
    def real_simtwo(self) -> bool:
        """The real SimTwo (``--simulator simtwo``), not the stand-in."""
        return self.mode == REAL


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
        cal, bag = "auto", str(Path(bag).resolve())
    if getattr(args, "save_bag", None) and Path(args.save_bag).exists():
        raise ConfigError(f"--save-bag {args.save_bag!r} exists already: give a new name (a bag is never overwritten)")
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
            pictures(args, graph, data, out_dir, log_dir, notes)
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


def _constraints(calibrate_as: str, real_simtwo: bool):
    """What raf calibrate holds on the calibration drive (``--calibrate-as``): SimTwo's constraints or None."""
    from ..simtwo_linux.scene import SIMTWO_CALIBRATION

    return SIMTWO_CALIBRATION if calibrate_as == "simtwo" or (calibrate_as == "auto" and real_simtwo) else None


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
            calib, keys = calibration_drive(args, plan, graph, log_dir, work, robot_file, nominal, out_dir, notes,
                                            constraints=_constraints(args.calibrate_as, plan.real_simtwo))
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
