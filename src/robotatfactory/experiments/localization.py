"""``raf experiment localization``: the paper's second validation test, made quantitative.

Runs, each in its own process against a private roscore on a free port: the stand-in simulator (``raf sim``,
lockstep, LIDAR beacons in the team areas), the bridge (``raf bridge``) and the localization
(``raf localize`` with every method computed). This process drives the reference route
(:mod:`robotatfactory.localization.route`, two laps round the whole field, the same every time) with a
pure-pursuit controller on the GROUND-TRUTH pose (so that control does not depend on what is measured),
records ground truth, odometry, every camera fix and the EKF, and prints position and heading errors (RMSE,
95th percentile, maximum) of odometry alone, the paper's closest-marker method, the closest marker with the
mount check, the all-marker PnP, the planar fit and the EKF. With ``--out DIR``: a trajectory figure, an
error-against-time figure, the TF tree (tf2_tools view_frames, PDF and PNG), an RViz screenshot taken under
Xvfb, the RViz configuration and the processes' logs.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

NAME = "localization"
HELP = "simulator + bridge + localization on a scripted route: errors of odometry, closest marker, all markers, EKF"
TARGETS = {
    "ekf_position_rmse_m": "<= 0.010 (issue 5)",
    "ekf_heading_rmse_deg": "<= 1.0 (issue 5)",
    "closest_over_ekf_position_rmse": ">= 3 (issue 5)",
    "odometry_over_ekf_end_position_error": ">= 10 (issue 5)",
}
METHODS = ("closest", "closest_checked", "all_pnp", "planar")
LABELS = {"odometry": "odometry alone", "closest": "closest marker (paper)", "closest_checked":
          "closest marker + mount check", "all_pnp": "all-marker PnP", "planar": "planar fit (mount fixed)",
          "ekf": "EKF (odometry + planar fixes + beacons)"}


def add_arguments(parser) -> None:
    parser.add_argument("--laps", type=int, default=2, help="laps of the reference loop (default 2)")
    parser.add_argument("--speed", type=float, default=0.2, help="cruise speed, m/s (default 0.2)")
    parser.add_argument("--seed", type=int, default=0, help="simulator seed (sensor noise, parts)")
    parser.add_argument("--no-beacons", action="store_true", help="no LIDAR beacons in the team areas")
    parser.add_argument("--calibration-error", default="0.01,-0.005", metavar="TRACK,RADIUS",
                        help="relative errors of the robot's nominal geometry (what the bridge's odometry and the "
                             "filter use) against the simulated robot: the simulated track is (1 + TRACK) and the "
                             "wheel radius (1 + RADIUS) times the nominal ones (default 0.01,-0.005: a robot "
                             "calibrated to 1 %% and 0.5 %%; 0,0 for the nominal robot, whose odometry in the "
                             "stand-in simulator is almost perfect)")
    parser.add_argument("--set", metavar="NAME=VALUE", action="append", default=[],
                        help="a localization setting for the node, e.g. node/use_lidar=false (repeatable)")
    parser.add_argument("--timeout", type=float, default=900.0, help="wall seconds for the whole drive (default 900)")
    parser.add_argument("--no-rviz", action="store_true", help="skip the RViz screenshot")
    parser.add_argument("--no-tf-tree", action="store_true", help="skip the TF tree")


# ------------------------------------------------------------------------------------------- recording


class Recorder:
    """The experiment's ROS node: drives the route on ground truth and records every pose stream."""

    def __init__(self, route_pts, speed: float, robot):
        import rospy
        from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
        from nav_msgs.msg import Odometry

        from ..localization.geometry import inv
        from ..localization.route import PurePursuit

        self.rospy = rospy
        self.Twist = Twist
        self.pp = PurePursuit(route_pts, speed=speed)
        self.T_cam_base = inv(robot.camera.base_to_optical())
        self.lock = threading.Lock()
        self.data = {k: [] for k in ("gt", "odom", "ekf", "camera_pose", *METHODS)}
        self.cmd = rospy.Publisher("cmd_vel", Twist, queue_size=5)
        self.done_t: float | None = None
        self.subs = [rospy.Subscriber("ground_truth", Odometry, self._on_gt, queue_size=50, tcp_nodelay=True),
                     rospy.Subscriber("odom", Odometry, self._rec("odom"), queue_size=100),
                     rospy.Subscriber("pose", PoseWithCovarianceStamped, self._rec("ekf"), queue_size=100),
                     rospy.Subscriber("camera_pose", PoseWithCovarianceStamped, self._on_camera, queue_size=50)]
        self.subs += [rospy.Subscriber(f"aruco/fixes/{m}", PoseWithCovarianceStamped, self._rec(m), queue_size=50)
                      for m in METHODS]
        from diagnostic_msgs.msg import DiagnosticArray

        self.diag: dict[str, str] = {}
        self.subs.append(rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diag, queue_size=20))

    def _on_diag(self, msg):
        for st in msg.status:
            if "raf_localization" in st.name:
                with self.lock:
                    self.diag.update({kv.key: kv.value for kv in st.values})

    @staticmethod
    def _planar(msg) -> tuple[float, float, float, float]:
        p = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
        from ..ros.messages import quaternion_yaw

        return (msg.header.stamp.to_sec(), p.position.x, p.position.y, quaternion_yaw(p.orientation))

    def _rec(self, key):
        def cb(msg):
            row = self._planar(msg)
            if key in ("ekf", *METHODS):
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
            self.data["camera_pose"].append((msg.header.stamp.to_sec(),) + base_from_camera(T, self.T_cam_base)
                                            + (p.z,))

    def _on_gt(self, msg):
        row = self._planar(msg)
        with self.lock:
            self.data["gt"].append(row)
        v, w = self.pp.command(row[1:])
        if self.pp.done and self.done_t is None:
            self.done_t = row[0]
        cmd = self.Twist()
        cmd.linear.x, cmd.angular.z = v, w
        self.cmd.publish(cmd)

    def stop(self):
        for s in self.subs:
            s.unregister()

    def arrays(self) -> dict:
        with self.lock:
            return {k: np.array(v, dtype=float) if v else np.zeros((0, 4)) for k, v in self.data.items()}


# ------------------------------------------------------------------------------------------- processes


class Procs:
    def __init__(self, log_dir: Path):
        self.log_dir = log_dir
        self.procs: list[tuple[str, subprocess.Popen]] = []

    def start(self, name: str, cmd: list[str], env: dict) -> subprocess.Popen:
        log = open(self.log_dir / f"{name}.log", "wb")
        p = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        self.procs.append((name, p))
        return p

    def check(self) -> None:
        for name, p in self.procs:
            if p.poll() is not None and name in ("sim", "bridge", "localize"):
                raise RuntimeError(f"{name} exited early with code {p.returncode}:\n{self.tail(name)}")

    def tail(self, name: str, n: int = 25) -> str:
        try:
            return "\n".join((self.log_dir / f"{name}.log").read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""

    def stop_all(self) -> None:
        from ..ros.master import stop_process

        for name, p in reversed(self.procs):
            stop_process(p)


def _raf(*args: str) -> list[str]:
    return [sys.executable, "-m", "robotatfactory", *args]


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
    ekf_rmse = out.get("ekf_position_rmse_m", math.nan)
    out["closest_over_ekf_position_rmse"] = out.get("closest_position_rmse_m", math.nan) / ekf_rmse
    out["odometry_over_ekf_end_position_error"] = (out.get("odometry_end_position_error_m", math.nan)
                                                   / max(out.get("ekf_end_position_error_m", math.nan), 1e-6))
    out["ekf_position_rmse_target_met"] = bool(ekf_rmse <= 0.010)
    out["ekf_heading_rmse_target_met"] = bool(out.get("ekf_heading_rmse_deg", math.inf) <= 1.0)
    out["ekf_3x_closest_target_met"] = bool(out["closest_over_ekf_position_rmse"] >= 3)
    out["ekf_10x_odometry_end_target_met"] = bool(out["odometry_over_ekf_end_position_error"] >= 10)
    return errs, out


def table(out: dict) -> str:
    rows = ["| method | samples | position RMSE / p95 / max (cm) | heading RMSE / p95 / max (deg) |",
            "|---|---|---|---|"]
    for m in ("odometry", *METHODS, "ekf"):
        if f"{m}_samples" not in out:
            continue
        g = lambda k: out.get(f"{m}_{k}", math.nan)  # noqa: E731
        rows.append(f"| {LABELS[m]} | {out[f'{m}_samples']} | {100 * g('position_rmse_m'):.2f} / "
                    f"{100 * g('position_p95_m'):.2f} / {100 * g('position_max_m'):.2f} | "
                    f"{g('heading_rmse_deg'):.2f} / {g('heading_p95_deg'):.2f} / {g('heading_max_deg'):.2f} |")
    return "\n".join(rows)


# ------------------------------------------------------------------------------------------- figures


def figures(d: dict, errs: dict, field, route_pts, out_dir: Path, t_end: float | None) -> None:
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
    ax.set_title("raf experiment localization: trajectories in map")
    fig.tight_layout()
    fig.savefig(out_dir / "localization_trajectory.png", dpi=110)
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
    a1.set_title("errors against ground truth (dashed: the 1 cm / 1 deg targets of the EKF)")
    fig.tight_layout()
    fig.savefig(out_dir / "localization_errors.png", dpi=110)
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


def save_debug_image(path: Path, notes: list) -> None:
    """One aruco/debug_image frame (the paper's figure 6) as PNG."""
    import rospy
    from sensor_msgs.msg import Image

    try:
        msg = rospy.wait_for_message("aruco/debug_image", Image, timeout=10.0)
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


def run(args, out_dir: Path | None) -> dict:
    from ..errors import ConfigError
    from ..field import load_field
    from ..localization.route import LOOP, route
    from ..ros.master import PrivateMaster, free_port
    from ..robot import load_robot

    if args.laps < 1 or not 0.02 <= args.speed <= 0.5:
        raise ConfigError("--laps must be >= 1 and --speed in 0.02..0.5 m/s")
    field = load_field(args.field)
    robot = load_robot()
    try:
        track_err, radius_err = (float(v) for v in args.calibration_error.split(","))
    except ValueError:
        raise ConfigError(f"--calibration-error {args.calibration_error!r}: expected TRACK,RADIUS, e.g. 0.01,-0.005")
    if not (abs(track_err) < 0.2 and abs(radius_err) < 0.2):
        raise ConfigError("--calibration-error: each relative error must be within +-0.2")
    pts = route(args.laps)
    work = Path(tempfile.mkdtemp(prefix="raf-exp-loc-"))
    log_dir = (out_dir / "logs") if out_dir else work
    log_dir.mkdir(parents=True, exist_ok=True)
    master = PrivateMaster().start()
    procs = Procs(log_dir)
    rec = None
    notes = []
    ok = False
    try:
        env = master.env()
        bport, sport, cport = free_port(__import__("socket").SOCK_DGRAM), free_port(__import__("socket").SOCK_DGRAM), free_port()
        cam = f"tcp://127.0.0.1:{cport}"
        x0, y0 = LOOP[0]
        start = f"{x0},{y0},{math.pi / 2}"
        procs.start("bridge", _raf("--field", args.field, "bridge", "--port", str(bport), "--camera", cam,
                                   "--sim-host", "127.0.0.1"), env)
        loc_args = ["--field", args.field, "localize", "--set", "node/all_methods=true"]
        for s in args.set:
            loc_args += ["--set", s]
        procs.start("localize", _raf(*loc_args), env)
        time.sleep(3.0)  # let the bridge bind its port before the simulator starts sending
        sim_args = ["--field", args.field, "sim", "--port", str(sport), "--bridge", f"127.0.0.1:{bport}",
                    "--camera-bind", cam, "--no-server", "--lockstep", "--lockstep-timeout", "2.0",
                    f"--start-pose={start}", "--seed", str(args.seed), "--status-every", "5"]
        if not args.no_beacons:
            sim_args.append("--beacons")
        if track_err or radius_err:
            import json
            from importlib import resources

            raw = json.loads((resources.files("robotatfactory") / "data" / "robot_simtwo.json").read_text())
            raw["track"] = raw["track"] * (1 + track_err)
            raw["wheel_radius"] = raw["wheel_radius"] * (1 + radius_err)
            raw["description"] = (f"the nominal robot with its track {100 * track_err:+.2f} % and wheel radius "
                                  f"{100 * radius_err:+.2f} % (raf experiment localization --calibration-error)")
            robot_file = work / "robot_sim.json"
            robot_file.write_text(json.dumps(raw, indent=1))
            sim_args += ["--robot", str(robot_file)]
        procs.start("sim", _raf(*sim_args), env)
        master.use_in_this_process()
        import rospy

        rospy.init_node("raf_experiment_localization", anonymous=True, disable_signals=True)
        rec = Recorder(pts, args.speed, robot)
        wall0 = time.monotonic()
        last_report = wall0
        while rec.done_t is None:
            procs.check()
            now = time.monotonic()
            if now - wall0 > args.timeout:
                notes.append(f"timeout after {args.timeout:.0f} wall s at {100 * rec.pp.progress:.0f} % of the route")
                break
            if now - last_report > 15:
                last_report = now
                d = rec.arrays()
                ts = d["gt"][-1, 0] if len(d["gt"]) else 0.0
                print(f"  route {100 * rec.pp.progress:5.1f} %, sim time {ts:6.1f} s, {len(d['planar'])} planar "
                      f"fixes, {len(d['ekf'])} EKF poses", flush=True)
            time.sleep(0.2)
        for _ in range(10):  # stop the robot
            rec.cmd.publish(rec.Twist())
            time.sleep(0.05)
        time.sleep(1.0)
        if out_dir is not None:
            out_dir.mkdir(parents=True, exist_ok=True)
            save_debug_image(out_dir / "localization_debug_image.png", notes)
            cfg = out_dir / "localization.rviz"
            d = rec.arrays()
            # look over the robot's shoulder at what its camera sees (the paper's figure 7)
            x, y, th = d["gt"][-1, 1:4] if len(d["gt"]) else (0.0, 0.0, 0.0)
            fx, fy = x + 0.25 * math.cos(th), y + 0.25 * math.sin(th)
            view = RVIZ.replace("X: 0.0\n        Y: -0.15", f"X: {fx:.3f}\n        Y: {fy:.3f}")
            view = view.replace("Yaw: 4.71", f"Yaw: {(th + math.pi) % (2 * math.pi):.3f}")
            cfg.write_text(view)
            if not args.no_tf_tree:
                why = tf_tree(env, out_dir, log_dir)
                if why:
                    notes.append(f"TF tree: {why}")
            if not args.no_rviz:
                why = rviz_screenshot(env, cfg, out_dir / "localization_rviz.png", log_dir)
                if why:
                    notes.append(f"RViz screenshot: {why}")
        data = rec.arrays()
        done_t = rec.done_t
        with rec.lock:
            diag = dict(rec.diag)
        ok = len(data["gt"]) >= 10
    finally:
        if rec is not None:
            rec.stop()
        procs.stop_all()
        master.cleanup()
        if ok:
            shutil.rmtree(work, ignore_errors=True)  # logs live in out_dir/logs when --out is given
        else:
            print(f"logs: {log_dir}", file=sys.stderr)
    if len(data["gt"]) < 10:
        raise RuntimeError("no ground truth recorded: did the simulator and the bridge run? "
                           f"(logs in {log_dir})")
    errs, out = analyse(data, done_t)
    out = {"laps": args.laps, "speed_m_per_s": args.speed, "controller": "pure pursuit on ground truth",
           "beacons": not args.no_beacons, "sim_track_error_fraction": track_err,
           "sim_wheel_radius_error_fraction": radius_err, **out}
    print(table(out))
    for n in notes:
        print(f"note: {n}")
    if out_dir is not None:
        figures(data, errs, field, pts, out_dir, done_t)
        (out_dir / "localization_table.md").write_text(table(out) + "\n")
        np.savez_compressed(out_dir / "localization_data.npz", **{k: v for k, v in data.items()})
    for k in sorted(diag):  # the node's counters at the end: frames, fixes, rejections by reason, filter
        if k.startswith(("rejected_", "filter_")) or k in ("frames", "fixes", "beacons_seen", "beacons_used",
                                                           "frame_ms_median", "scans"):
            try:
                out[f"node_{k.replace(':', '_')}"] = float(diag[k]) if "." in diag[k] else int(diag[k])
            except ValueError:
                pass
    out["notes"] = "; ".join(notes)
    return out
