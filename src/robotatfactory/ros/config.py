"""The bridge's settings: one typed object (:class:`BridgeSettings`) for the bridge node and its camera process.

Every setting has its default, meaning and allowed values here and nowhere else; the robot's geometry, its
LIDAR's mount and range and the camera's mount and intrinsics are the robot file's (``data/robot_*.json``:
:class:`~robotatfactory.robot.RobotSpec`, :class:`~robotatfactory.robot.CameraSpec` declare what they mean),
so here they are *unset* unless a user gives them. ``raf bridge`` fills the object from ``--config FILE`` (the
shape of ``config/bridge.yaml``, generated from this module) and ``--set camera/fx=283.5``, the node from its
ROS parameters (``~camera/fx`` on ROS 1, ``camera.fx`` on ROS 2), all through
:func:`robotatfactory.settings.build`: one validation, whose errors name the setting and what is allowed.

:func:`load_config` then resolves the settings against the robot file and the camera calibration
(``camera.calibration``, parsed once into the camera object ``raf localize`` makes of it too) into a
:class:`BridgeConfig`: what the node runs with. A camera value given explicitly wins over the calibration's.
Plain Python (no ROS import), unit-tested without ROS.
"""
from __future__ import annotations

import dataclasses
import ipaddress
import math
from dataclasses import dataclass
from typing import Any

from ..errors import ConfigError
from ..field import DEFAULT_FIELD
from ..robot import CameraSpec, LidarSpec, RobotSpec, load_robot
from ..pace import PaceSettings
from ..settings import build, describer, given, over, overlay, section, setting, tree
from ..sim.control import CONTROL_PORT_OFFSET
from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT

_TOPIC = r"[A-Za-z_/~][A-Za-z0-9_/]*"
_FRAME = r"[A-Za-z_][A-Za-z0-9_/]*"


def _topic(default: str, doc: str):
    return setting(default, doc, pattern=_TOPIC, what="a ROS name (letters, digits, _, / and ~)")


def _frame(default: str, doc: str = ""):
    return setting(default, doc, pattern=_FRAME, what="a frame id (letters, digits, _ and /, no leading /)")


@dataclass(frozen=True)
class Udp:
    """Where SensorFrames arrive (``udp.*``)."""

    bind_host: str = setting("auto", "auto: 127.0.0.1 while simulator.host is this machine, every interface when "
                                     "it is another; else the address to listen on")
    port: int = setting(BRIDGE_UDP_PORT, "SimTwo scripts send SensorFrames here (0: any free port)", lo=0,
                        hi=65535)
    max_datagram: int = setting(16384, "bytes; larger datagrams are rejected as oversized (a 360-ray frame is "
                                       "~2.9 KB)", lo=64, hi=65507)


@dataclass(frozen=True)
class Simulator:
    """The simulator the bridge talks to (``simulator.*``)."""

    host: str = setting(LOCALHOST, "accept SensorFrames from this host only (\"*\": any); replies go to the "
                                   "datagram's source")
    port: int = setting(0, "the simulator's source port; 0: bind to the first sender whose frames form a stream",
                        lo=0, hi=65535)
    reply_port: int = setting(0, "0: reply to the source port; else this port on the simulator's host (SimTwo: "
                                 f"{SIMTWO_UDP_PORT})", lo=0, hi=65535)
    control: str = setting(f"{LOCALHOST}:{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}",
                           "raf sim's control channel for the sim/* services (\"\" for none; SimTwo has none)",
                           pattern=r"|[A-Za-z0-9_.\-]+:\d{1,5}",
                           what="host:port of raf sim's control channel, e.g. "
                                f"{LOCALHOST}:{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}, or empty for none")


@dataclass(frozen=True)
class Stream:
    """How the SensorFrame stream is checked (``stream.*``, docs/reliability.md)."""

    reorder_window: int = setting(25, "frames: a late Seq up to this far behind is stale (reordered); the most a "
                                      "chain may skip", lo=1, hi=10 ** 6)
    restart_confirm: int = setting(3, "frames in a consistent chain that confirm a restart, a jump or a new "
                                      "sender", lo=1, hi=1000)
    max_jump: int = setting(250, "cycles: a Seq/Tms further ahead is held until restart_confirm frames confirm "
                                 "it", lo=1, hi=10 ** 9)
    takeover_after: float = setting(2.0, "wall s the bound sender must be silent before another sender may take "
                                         "over", lo=0.0)
    max_wheel_speed: float = setting(None, "rad/s: encoder totals moving faster are rejected (unset: twice the "
                                           "robot's motor's no-load speed, 54.4 for SimTwo's)", lo=0.0,
                                     lo_open=True, kind=float)


@dataclass(frozen=True)
class Watchdog:
    timeout: float = setting(0.5, "s of SIMULATION time: cmd_vel older than this -> replies carry V = W = 0",
                             lo=0.0, lo_open=True)


#: ``geometry.*``: the robot file's control period, physics step, wheel radius, track and ticks per revolution
Geometry = overlay(RobotSpec, ("control_period", "physics_step", "wheel_radius", "track", "ticks_per_rev"),
                   "Geometry")


@dataclass(frozen=True)
class Odometry:
    slip_var_per_m: float = setting(1e-4, "m^2 per m of wheel travel: odometry covariance growth", lo=0.0)
    track: float = setting(None, "m: the track odometry turns with (unset: the robot file's odometry_track; "
                                 "SimTwo's robot turns 2.1 % more than its 0.135 m wheel spacing says)",
                           lo=0.0, hi=10.0, lo_open=True, kind=float)


@dataclass(frozen=True)
class Lidar(overlay(LidarSpec, ("xyz", "fov_deg", "range_min", "range_max", "period"))):
    """The LIDAR (``lidar.*``): its mount and ranges are the robot file's unless given (the datagram carries
    only the ranges)."""

    enabled: bool = setting(True, "publish scan")
    mode: str = setting("sweep", "sweep: one time-ordered scan per completed sweep; cycle: every datagram's array "
                                 "as is", choices=("sweep", "cycle"))
    update: str = setting("sweep", "sweep: the simulator delivers all rays at once per period (SimTwo, raf sim's "
                                   "default); per_ray: each ray as soon as measured (raf sim --lidar-update "
                                   "per_ray)", choices=("sweep", "per_ray"))
    ray_timing: str = setting("rolling", "rolling: ray i measured at delivery - period + i*period/N (SimTwo); "
                                         "instant: all at delivery", choices=("rolling", "instant"))
    self_filter: bool = setting(True, "rays ending inside the robot's own footprint (wheels, base) are published "
                                      "as NaN")
    self_margin: float = setting(0.009, "m around the footprint: 5 sigma of the range noise at the wheels, < "
                                        "magnet face - base front", lo=0.0, hi=0.1)
    delivery_lag: float = setting(0.001, "s from the frame before a sweep's delivery to it (SimTwo: 1 ms); 0: "
                                         "unknown, bracket middle; at most the control period", lo=0.0, hi=10.0)


@dataclass(frozen=True)
class Camera(overlay(CameraSpec)):
    """The camera (``camera.*``): its mount and intrinsics are the robot file's, then the calibration's, unless
    given."""

    enabled: bool = setting(True, "subscribe to the camera and publish camera/image_raw and camera_info")
    endpoint: str = setting(f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}",
                            "SimTwo's ZMQ PUB (use the simulator's address when remote)",
                            pattern=r"(tcp|ipc|inproc)://\S+",
                            what=f"a ZMQ endpoint such as tcp://192.168.1.20:{CAMERA_ZMQ_PORT}")
    calibration: str = setting("", "a calibration file (raf calibrate): its mount, intrinsics and distortion over "
                                   "the robot file's (a camera value given here wins over it)")
    bracket: str = setting("elapsed", "how a frame's render time is found (docs/bridge.md, camera stamping): "
                                      "elapsed (SimTwo and raf sim) | following | nearest",
                           choices=("elapsed", "following", "nearest"))
    use_grid: bool = setting(False, "nearest/following only: lock onto a render grid of k/15 s of simulation time "
                                    "(only raf sim --camera-timing grid has one; SimTwo does not)")
    latency: float = setting(0.004, "s (wall): a frame's transport time, subtracted by the elapsed rule", lo=0.0,
                             hi=0.1)
    max_wait: float = setting(0.02, "s (wall): nearest only: longest wait for the SensorFrame after a frame",
                              lo=0.0, hi=1.0)
    process: str = setting("own", "where the camera half runs: own (a process of its own: 1.2 MB frames never "
                                  "hold the bridge's GIL) | bridge (the bridge's process, ROS 1: composed with raf "
                                  "compose, its images reach the other nodes in-process)", choices=("own", "bridge"))


@dataclass(frozen=True)
class Tf:
    publish_odom: bool = setting(True, "TF odom -> base_link (off when another node, e.g. an EKF, publishes it)")
    publish_field: bool = setting(True, "static TFs map -> aruco_<id> and the latched field/markers")
    map_to_odom: str = setting("none", "none (localization publishes it) | identity | first_ground_truth (demos "
                                       "only)", choices=("none", "identity", "first_ground_truth"))


@dataclass(frozen=True)
class Diagnostics:
    period: float = setting(1.0, "s (wall) between /diagnostics messages", lo=0.0, hi=60.0, lo_open=True)
    stale_warn: float = setting(0.5, "s (wall) without a SensorFrame: WARN", lo=0.0, lo_open=True)
    stale_error: float = setting(2.0, "s (wall) without a SensorFrame: ERROR (at least stale_warn)", lo=0.0,
                                 lo_open=True)


@dataclass(frozen=True)
class Topics:
    """Topic names (``topics.*``): relative ones live in the node's namespace; ``/clock`` and ``/diagnostics``
    are global by ROS convention."""

    clock: str = _topic("/clock", "rosgraph_msgs/Clock: every frame's Tms")
    scan: str = _topic("scan", "sensor_msgs/LaserScan")
    odom: str = _topic("odom", "nav_msgs/Odometry: wheel odometry")
    ground_truth: str = _topic("ground_truth", "nav_msgs/Odometry: the simulator's pose (evaluation only)")
    parts_ground_truth: str = _topic("ground_truth/parts", "geometry_msgs/PoseArray: the parts' poses (referee)")
    joint_states: str = _topic("joint_states", "sensor_msgs/JointState: the wheels")
    contact: str = _topic("contact", "std_msgs/Bool: the micro switch")
    magnet_state: str = _topic("electromagnet/state", "std_msgs/Bool: the magnet as the simulator applied it")
    image: str = _topic("camera/image_raw", "sensor_msgs/Image")
    camera_info: str = _topic("camera/camera_info", "sensor_msgs/CameraInfo")
    cmd_vel: str = _topic("cmd_vel", "geometry_msgs/Twist in")
    magnet: str = _topic("electromagnet", "std_msgs/Bool in: the magnet's command")
    field_markers: str = _topic("field/markers", "visualization_msgs/MarkerArray, latched")
    diagnostics: str = _topic("/diagnostics", "diagnostic_msgs/DiagnosticArray")


@dataclass(frozen=True)
class Frames:
    """Frame ids (``frames.*``): robot frames get ``frame_prefix/`` in front; ``map`` and the markers' do not."""

    map: str = _frame("map")
    odom: str = _frame("odom")
    base_link: str = _frame("base_link")
    laser: str = _frame("laser")
    camera_link: str = _frame("camera_link")
    camera_optical: str = _frame("camera_optical")
    left_wheel: str = _frame("left_wheel")
    right_wheel: str = _frame("right_wheel")
    marker_prefix: str = _frame("aruco_", "marker k's frame is this followed by k")


ROBOT_FRAMES = ("odom", "base_link", "laser", "camera_link", "camera_optical", "left_wheel", "right_wheel")


@dataclass(frozen=True)
class BridgeSettings:
    """Every setting of the bridge (and its camera process)."""

    field: str = setting(DEFAULT_FIELD, "competition map (shipped name or a field .json): static TFs map -> "
                                        "aruco_<id>, field/markers")
    robot: str = setting("simtwo", "robot file the geometry, LIDAR and camera come from (shipped name or a .json "
                                   "path)")
    frame_prefix: str = setting("", "\"robot1\" makes robot1/odom, robot1/base_link, ... (several robots, one "
                                    "bridge each)", pattern=r"|[A-Za-z_][A-Za-z0-9_/]*[A-Za-z0-9_]",
                                what="empty or a frame prefix such as robot1 (letters, digits, _ and /, no "
                                     "leading or trailing /)")
    log_period: float = setting(5.0, "s: each kind of warning is logged at most once per period (with a count)",
                                lo=0.0)
    udp: Udp = section(Udp, "where SensorFrames arrive")
    simulator: Simulator = section(Simulator, "the simulator")
    stream: Stream = section(Stream, "the SensorFrame stream's checks")
    watchdog: Watchdog = section(Watchdog, "the command watchdog")
    geometry: Geometry = section(Geometry, "unset: the robot file's")
    odometry: Odometry = section(Odometry, "wheel odometry")
    lidar: Lidar = section(Lidar, "the LIDAR; mount and ranges unset: the robot file's")
    camera: Camera = section(Camera, "the camera; mount and intrinsics unset: the robot file's, then the "
                                     "calibration's")
    tf: Tf = section(Tf, "TF")
    diagnostics: Diagnostics = section(Diagnostics, "/diagnostics")
    pace: PaceSettings = section(PaceSettings, "pacing by simulation time (the bridge replies to frame k once "
                                               "the agent paced it; the camera side waits for CamN frames)")
    topics: Topics = section(Topics, "topic names")
    frames: Frames = section(Frames, "frame ids")


# ---- resolved against the robot file ------------------------------------------------------------------

@dataclass(frozen=True)
class BridgeConfig:
    """What the bridge runs with. ``settings``: every setting with its value (the robot file's and the
    calibration's filled in); ``given``: the settings as given; ``robot``: the robot file with the given
    geometry, LIDAR and camera over it (``robot.camera`` is the camera the TF and camera_info describe). The
    resolved settings' sections read through: ``cfg.udp.port``, ``cfg.camera.endpoint``."""

    settings: BridgeSettings
    given: BridgeSettings
    robot: RobotSpec
    bind_host: str  # the address listened on (udp.bind_host resolved)
    sim_host: str  # the simulator's address, or "*": any
    sim_control: tuple[str, int] | None  # raf sim's control channel (the sim/* services); None: off
    topics: dict
    frames: dict  # frame ids with the prefix applied

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__") or name == "settings":
            raise AttributeError(name)
        return getattr(self.settings, name)

    @property
    def source(self) -> tuple[str, int] | None:
        """The configured sender (host, port), or None: the first consistent one binds the stream."""
        port = self.settings.simulator.port
        return (self.sim_host, port) if self.sim_host != "*" and port else None

    @property
    def max_ticks_per_s(self) -> float:
        return self.stream.max_wheel_speed * self.geometry.ticks_per_rev / (2 * math.pi)

    @property
    def control_period_ms(self) -> int:
        return int(round(self.geometry.control_period * 1000))

    def marker_frame(self, marker_id: int) -> str:
        return f"{self.frames['marker_prefix']}{marker_id}"

    @property
    def params(self) -> dict:
        """Every setting with its value, as the nested parameter tree (``raf bridge --print-params``)."""
        return tree(self.settings)

    def given_params(self) -> dict:
        """The settings as given (what :func:`load_config` turns into this same config again)."""
        return given(self.given)

    def flat_params(self) -> dict[str, Any]:
        """``{"udp/port": BRIDGE_UDP_PORT, ...}``: the resolved tree as flat parameter names (without the ``~``)."""
        from .mw.base import flatten

        return flatten(self.params, "/")


def _max_wheel_speed(r: RobotSpec) -> float:
    """Twice the free wheel's no-load speed at the motor's full voltage (rad/s): faster encoder counts are
    forged or corrupt (the stream's plausibility check)."""
    from ..sim.motor import MotorParams

    return round(2.0 * MotorParams.from_spec(r.motor).no_load_speed(), 1)


def _host(path: str, v: str, allow_any: bool) -> str:
    if allow_any and v in ("*", ""):
        return "*"
    try:
        ipaddress.ip_address(v)
    except ValueError:
        import socket

        try:
            return socket.gethostbyname(v)
        except OSError:
            raise ConfigError(f"setting {path}: {v!r} is neither an IPv4 address nor a resolvable host name"
                              + (" (use \"*\" to accept any host)" if allow_any else "")) from None
    return v


def _control(text: str) -> tuple[str, int] | None:
    if not text:
        return None
    host, port = text.rsplit(":", 1)
    if not 0 < int(port) <= 65535:
        raise ConfigError(f"setting simulator.control {text!r}: port must be 1..65535")
    return host, int(port)


def _robot(name: str) -> RobotSpec:
    try:
        return load_robot(name)
    except FileNotFoundError as e:
        raise ConfigError(f"setting robot: {e}") from None


def _camera(s: BridgeSettings, robot: RobotSpec) -> CameraSpec:
    """The robot file's camera, then the calibration's (``camera.calibration``: parsed once per process into the
    camera ``raf localize`` makes of it too), then the camera values given."""
    cam = robot.camera
    if s.camera.calibration:
        from ..localization.calibration import load_calibration

        try:
            cam = load_calibration(s.camera.calibration).apply(cam)
        except ConfigError as e:
            raise ConfigError(f"setting camera.calibration: {e}") from None
    return over(s.camera, cam)


def resolve(s: BridgeSettings) -> BridgeConfig:
    """The settings resolved against their robot file and calibration, with the rules between settings checked
    (errors name the settings)."""
    robot = _robot(s.robot)
    g = over(s.geometry, robot)
    robot = dataclasses.replace(g, lidar=over(s.lidar, robot.lidar), camera=_camera(s, robot))
    period, cam, lid = robot.control_period, robot.camera, robot.lidar
    if abs(period * 1000 - round(period * 1000)) > 1e-6:
        raise ConfigError(f"setting geometry.control_period must be whole milliseconds, got {period!r}")
    if robot.physics_step > period:
        raise ConfigError(f"setting geometry.physics_step ({robot.physics_step}) must be at most "
                          f"geometry.control_period ({period})")
    if s.lidar.delivery_lag > period:
        raise ConfigError(f"setting lidar.delivery_lag ({s.lidar.delivery_lag}) must be at most the control period "
                          f"({period})")
    if lid.range_min >= lid.range_max:
        raise ConfigError(f"setting lidar.range_min ({lid.range_min}) must be below lidar.range_max "
                          f"({lid.range_max})")
    if s.diagnostics.stale_error < s.diagnostics.stale_warn:
        raise ConfigError(f"setting diagnostics.stale_error ({s.diagnostics.stale_error}) must be >= "
                          f"diagnostics.stale_warn ({s.diagnostics.stale_warn})")
    if not (0 <= cam.cx <= cam.width and 0 <= cam.cy <= cam.height):
        raise ConfigError(f"settings camera.cx, camera.cy ({cam.cx}, {cam.cy}) must lie in the "
                          f"{cam.width}x{cam.height} image")
    _check_field(s.field)
    camera_fields = {f.name: getattr(cam, f.name) for f in dataclasses.fields(Camera) if hasattr(cam, f.name)}
    lidar_fields = {f.name: getattr(lid, f.name) for f in dataclasses.fields(Lidar) if hasattr(lid, f.name)}
    full = dataclasses.replace(
        s,
        geometry=Geometry(**{f.name: getattr(robot, f.name) for f in dataclasses.fields(Geometry)}),
        odometry=dataclasses.replace(s.odometry, track=s.odometry.track or robot.odometry_track),
        stream=dataclasses.replace(s.stream, max_wheel_speed=s.stream.max_wheel_speed or _max_wheel_speed(robot)),
        lidar=dataclasses.replace(s.lidar, **lidar_fields),
        camera=dataclasses.replace(s.camera, **camera_fields),
    )
    prefix = s.frame_prefix
    frames = {k: f"{prefix}/{v}" if prefix and k in ROBOT_FRAMES else v for k, v in tree(s.frames).items()}
    sim_host = _host("simulator.host", s.simulator.host, allow_any=True)
    if s.udp.bind_host != "auto":
        bind = _host("udp.bind_host", s.udp.bind_host, allow_any=False)
    else:  # loopback while the simulator is on this machine, every interface when it is another or any
        bind = "127.0.0.1" if sim_host != "*" and ipaddress.ip_address(sim_host).is_loopback else "0.0.0.0"
    return BridgeConfig(settings=full, given=s, robot=robot, bind_host=bind, sim_host=sim_host,
                        sim_control=_control(s.simulator.control), topics=tree(s.topics), frames=frames)


def load_config(overrides: dict | None = None) -> BridgeConfig:
    """The bridge's settings from a nested mapping (config/bridge.yaml's shape, ROS parameters, ``--set``;
    what it lacks keeps its default), validated and resolved."""
    return resolve(build(BridgeSettings, overrides or {}))


def check_camera_process(cfg: BridgeConfig, middleware: str) -> None:
    """ConfigError for ``camera.process: bridge`` (an enabled camera) on a ``middleware`` other than ROS 1: the
    camera half is then a second node in the bridge's process (:meth:`~.mw.base.Node.sibling`), and only rospy
    makes one in a process. ``raf bridge`` checks before the middleware starts, the node for a launch file."""
    if cfg.camera.enabled and cfg.camera.process == "bridge" and middleware != "ros1":
        raise ConfigError(f"camera.process: bridge: ROS 1 only (one node per process there); on "
                          f"{middleware} the camera runs in a process of its own (camera.process: own)")


def default_params() -> dict:
    """The node's parameters with their defaults (what ROS 2 declares; unset: None): every bridge setting."""
    return tree(BridgeSettings())


#: (description, (min, max) or None) of a parameter (``udp.port``): its setting's
describe_param = describer(BridgeSettings)

HEADER = """\
robotatfactory bridge: its settings (ROS parameters ~udp/port, ~camera/fx, ...) with their defaults.
GENERATED from src/robotatfactory/ros/config.py by `raf bridge --print-params --defaults > config/bridge.yaml`:
edit that module, then regenerate (tests/test_bridge_config.py fails while this file is out of date).
launch/bridge.launch loads this file into the node's namespace; `raf bridge --config FILE` takes a file of
the same shape, `--set camera/fx=283.5` single values. The geometry, the LIDAR's and the camera's values are
unset here: they come from the robot file (src/robotatfactory/data/robot_simtwo.json) and the calibration.
A bad value stops the node with an error that names the setting. See docs/bridge.md."""


def _check_field(name: str) -> None:
    from ..field import load_field
    from ..field.loader import FieldError

    try:
        load_field(name)
    except (FieldError, FileNotFoundError) as e:
        raise ConfigError(f"setting field: {e}") from None
