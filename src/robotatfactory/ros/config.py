"""The bridge's settings: defaults (from the robot spec), validation, and the flat ROS parameter names.

Plain Python (no rospy import), so it is unit-tested without ROS. The node reads its private parameters
(``~udp/port``, ``~camera/fx``, ...) into a nested dict and calls :func:`load_config`; ``raf bridge`` builds
the same dict from ``config/bridge.yaml`` and its options. Every bad value raises
:class:`~robotatfactory.errors.ConfigError` naming the parameter (``~camera/fx``) and what is allowed.
"""
from __future__ import annotations

import copy
import ipaddress
import math
import re
from dataclasses import dataclass, replace
from typing import Any

from ..errors import ConfigError
from ..robot import CameraSpec, RobotSpec, load_robot
from ..sim.control import CONTROL_PORT_OFFSET
from ..simtwo.ports import BRIDGE_UDP_PORT, CAMERA_ZMQ_PORT, LOCALHOST, SIMTWO_UDP_PORT

#: Topic names (relative: a namespace puts each robot's bridge in its own space). ``/clock`` and
#: ``/diagnostics`` are global by ROS convention.
DEFAULT_TOPICS = {
    "clock": "/clock",
    "scan": "scan",
    "odom": "odom",
    "ground_truth": "ground_truth",
    "parts_ground_truth": "ground_truth/parts",
    "joint_states": "joint_states",
    "contact": "contact",
    "magnet_state": "electromagnet/state",
    "image": "camera/image_raw",
    "camera_info": "camera/camera_info",
    "cmd_vel": "cmd_vel",
    "magnet": "electromagnet",
    "field_markers": "field/markers",
    "diagnostics": "/diagnostics",
}

#: Frame ids. Robot frames get ``frame_prefix/`` in front; ``map`` and the markers' frames do not.
DEFAULT_FRAMES = {
    "map": "map",
    "odom": "odom",
    "base_link": "base_link",
    "laser": "laser",
    "camera_link": "camera_link",
    "camera_optical": "camera_optical",
    "left_wheel": "left_wheel",
    "right_wheel": "right_wheel",
    "marker_prefix": "aruco_",
}
ROBOT_FRAMES = ("odom", "base_link", "laser", "camera_link", "camera_optical", "left_wheel", "right_wheel")


def _max_wheel_speed(r: RobotSpec) -> float:
    """Twice the free wheel's no-load speed at the motor's full voltage (rad/s): faster encoder counts are
    forged or corrupt (the stream's plausibility check)."""
    from ..sim.motor import MotorParams

    return round(2.0 * MotorParams.from_spec(r.motor).no_load_speed(), 1)


def default_params(robot: RobotSpec | None = None) -> dict:
    """The full nested parameter tree with its defaults (the robot spec gives the geometry)."""
    r = robot or load_robot()
    cam, lid = r.camera, r.lidar
    return {
        "field": "rules2026",
        "robot": "simtwo",
        "frame_prefix": "",
        "udp": {"bind_host": "auto", "port": BRIDGE_UDP_PORT, "max_datagram": 16384},
        "simulator": {"host": LOCALHOST, "port": 0, "reply_port": 0,
                      "control": f"{LOCALHOST}:{SIMTWO_UDP_PORT + CONTROL_PORT_OFFSET}"},
        "stream": {"reorder_window": 25, "restart_confirm": 3, "max_jump": 250, "takeover_after": 2.0,
                   "max_wheel_speed": _max_wheel_speed(r)},
        "watchdog": {"timeout": 0.5},
        "geometry": {
            "control_period": r.control_period, "physics_step": r.physics_step,
            "wheel_radius": r.wheel_radius, "track": r.track, "ticks_per_rev": r.ticks_per_rev,
        },
        "odometry": {"slip_var_per_m": 1e-4, "track": r.odometry_track},
        "lidar": {
            "enabled": True, "xyz": list(lid.xyz), "fov_deg": lid.fov_deg, "range_min": lid.range_min,
            "range_max": lid.range_max, "period": lid.period, "mode": "sweep", "update": "sweep",
            "ray_timing": "rolling", "self_filter": True, "self_margin": 0.009,
            "delivery_lag": 0.001,
        },
        "camera": {
            "enabled": True, "endpoint": f"tcp://{LOCALHOST}:{CAMERA_ZMQ_PORT}", "calibration": "",
            "xyz": list(cam.xyz), "pitch_down_deg": cam.pitch_down_deg, "roll_deg": cam.roll_deg,
            "distortion": list(cam.distortion),
            "width": cam.width, "height": cam.height, "fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy,
            "bottom_up": cam.bottom_up, "render_fps": cam.render_fps, "decimation": cam.decimation,
            "use_grid": False, "bracket": "elapsed", "max_wait": 0.02, "latency": 0.004,
        },
        "tf": {"publish_odom": True, "publish_field": True, "map_to_odom": "none"},
        "diagnostics": {"period": 1.0, "stale_warn": 0.5, "stale_error": 2.0},
        "log_period": 5.0,
        "topics": dict(DEFAULT_TOPICS),
        "frames": dict(DEFAULT_FRAMES),
    }


# ---- validation ----------------------------------------------------------------------------------------

def _name(path: tuple[str, ...]) -> str:
    return "~" + "/".join(path)


def merge(defaults: dict, overrides: dict | None, path: tuple[str, ...] = ()) -> dict:
    """Overrides onto defaults; an unknown key or a section given as a scalar is an error naming it."""
    out = copy.deepcopy(defaults)
    for k, v in (overrides or {}).items():
        p = path + (str(k),)
        if k not in defaults:
            known = ", ".join(sorted(defaults))
            raise ConfigError(f"unknown parameter {_name(p)}; known here: {known}")
        if isinstance(defaults[k], dict):
            if not isinstance(v, dict):
                raise ConfigError(f"parameter {_name(p)} is a section ({', '.join(sorted(defaults[k]))}), "
                                  f"got {v!r}")
            out[k] = merge(defaults[k], v, p)
        else:
            out[k] = v
    return out


#: The numeric ranges the validation below allows, by parameter path (recorded as it runs): ROS 2 declares
#: the parameters with them (:func:`describe_param`).
RANGES: dict[tuple[str, ...], tuple[float, float]] = {}


def _note_range(path, lo, hi, big=1e9) -> None:
    if lo is not None or hi is not None:
        RANGES[path] = (-big if lo is None else lo, big if hi is None else hi)


def describe_param(flat: str) -> tuple[str, tuple[float, float] | None]:
    """(description, (min, max) or None) of a parameter (``udp.port``): the comment in config/bridge.yaml
    and the range the validation allows."""
    from ..settings import yaml_comments

    global _COMMENTS
    if _COMMENTS is None:
        from .master import ROOT

        _COMMENTS = yaml_comments(ROOT / "config" / "bridge.yaml")
        load_config({})  # records RANGES
    return _COMMENTS.get(flat, ""), RANGES.get(tuple(flat.split(".")))


_COMMENTS: dict | None = None


def _real(d: dict, path: tuple[str, ...], lo: float | None = None, hi: float | None = None,
          lo_open: bool = False) -> float:
    _note_range(path, lo, hi)
    v = _get(d, path)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ConfigError(f"parameter {_name(path)} must be a number, got {v!r}")
    v = float(v)
    if not math.isfinite(v):
        raise ConfigError(f"parameter {_name(path)} must be finite, got {v!r}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ConfigError(f"parameter {_name(path)} must be {'>' if lo_open else '>='} {lo}, got {v!r}")
    if hi is not None and v > hi:
        raise ConfigError(f"parameter {_name(path)} must be <= {hi}, got {v!r}")
    return v


def _int(d: dict, path: tuple[str, ...], lo: int | None = None, hi: int | None = None) -> int:
    _note_range(path, lo, hi, big=2**31 - 1)
    v = _get(d, path)
    if isinstance(v, bool) or not isinstance(v, int):
        if isinstance(v, float) and v.is_integer():
            v = int(v)
        else:
            raise ConfigError(f"parameter {_name(path)} must be an integer, got {v!r}")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        raise ConfigError(f"parameter {_name(path)} must be in [{lo}, {hi}], got {v!r}")
    return v


def _bool(d: dict, path: tuple[str, ...]) -> bool:
    v = _get(d, path)
    if not isinstance(v, bool):
        raise ConfigError(f"parameter {_name(path)} must be true or false, got {v!r}")
    return v


def _str(d: dict, path: tuple[str, ...], pattern: str | None = None, what: str = "",
         allowed: tuple[str, ...] | None = None) -> str:
    v = _get(d, path)
    if not isinstance(v, str):
        raise ConfigError(f"parameter {_name(path)} must be a string, got {v!r}")
    if allowed is not None and v not in allowed:
        raise ConfigError(f"parameter {_name(path)} must be one of {', '.join(allowed)}; got {v!r}")
    if pattern is not None and not re.fullmatch(pattern, v):
        raise ConfigError(f"parameter {_name(path)} must be {what}; got {v!r}")
    return v


def _xyz(d: dict, path: tuple[str, ...]) -> tuple[float, float, float]:
    v = _get(d, path)
    if not isinstance(v, (list, tuple)) or len(v) != 3 or not all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v):
        raise ConfigError(f"parameter {_name(path)} must be a list of three numbers [x, y, z] in metres, got {v!r}")
    return (float(v[0]), float(v[1]), float(v[2]))


def _distortion(d: dict, path: tuple[str, ...]) -> tuple[float, ...]:
    v = _get(d, path)
    if not isinstance(v, (list, tuple)) or not 1 <= len(v) <= 5 or not all(
            isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c) for c in v):
        raise ConfigError(f"parameter {_name(path)} must be a list of up to five numbers [k1, k2, p1, p2, k3] "
                          f"(OpenCV, ROS plumb_bob), got {v!r}")
    return tuple(float(c) for c in v) + (0.0,) * (5 - len(v))


def _get(d: dict, path: tuple[str, ...]) -> Any:
    for k in path:
        d = d[k]
    return d


_NAME = r"[A-Za-z_/~][A-Za-z0-9_/]*"
_FRAME = r"[A-Za-z_][A-Za-z0-9_/]*"


def _host(d: dict, path: tuple[str, ...], allow_any: bool) -> str:
    v = _str(d, path)
    if allow_any and v in ("*", ""):
        return "*"
    try:
        ipaddress.ip_address(v)
    except ValueError:
        import socket

        try:
            return socket.gethostbyname(v)
        except OSError:
            raise ConfigError(f"parameter {_name(path)}: {v!r} is neither an IPv4 address nor a resolvable host "
                              + ("name (use \"*\" to accept any host)" if allow_any else "name")) from None
    return v


def _bind_host(p: dict) -> str:
    """``udp/bind_host``: ``auto`` listens on loopback when the simulator is on this machine (the default), on
    every interface when ``simulator/host`` names another machine or any host; else the address given."""
    if _str(p, ("udp", "bind_host")) != "auto":
        return _host(p, ("udp", "bind_host"), allow_any=False)
    sim = _host(p, ("simulator", "host"), allow_any=True)
    return "127.0.0.1" if sim != "*" and ipaddress.ip_address(sim).is_loopback else "0.0.0.0"


# ---- the typed result ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class BridgeConfig:
    """Validated settings. ``params`` is the full nested tree (for writing back to the parameter server)."""

    params: dict
    field: str
    robot: str
    frame_prefix: str
    bind_host: str
    port: int
    max_datagram: int
    sim_host: str  # "*" = any
    reply_port: int
    reorder_window: int
    restart_confirm: int
    watchdog_timeout: float  # s of simulation time
    control_period: float
    physics_step: float
    wheel_radius: float
    track: float
    ticks_per_rev: int
    slip_var_per_m: float
    odometry_track: float  # m: the track odometry turns with (the robot file's measured one; geometry/track: TF)
    lidar_enabled: bool
    lidar_xyz: tuple[float, float, float]
    lidar_fov_deg: float
    lidar_range_min: float
    lidar_range_max: float
    lidar_period: float
    lidar_mode: str
    lidar_update: str  # "sweep": all rays delivered at once per period (SimTwo) | "per_ray"
    lidar_ray_timing: str  # "rolling": ray i measured at t_u - P + i*P/N (SimTwo) | "instant": all at t_u
    lidar_self_filter: bool  # rays ending inside the robot's footprint published as NaN
    lidar_self_margin: float  # m, added around the footprint
    lidar_delivery_lag: float  # s from the frame before a sweep's delivery to it (SimTwo 0.001); 0 = unknown
    camera_enabled: bool
    camera_endpoint: str
    camera_xyz: tuple[float, float, float]
    camera_pitch_down_deg: float
    camera_roll_deg: float  # about the optical axis (CameraSpec)
    distortion: tuple[float, ...]  # OpenCV (k1, k2, p1, p2, k3): CameraInfo.D
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    bottom_up: bool
    render_fps: float
    decimation: int
    use_grid: bool
    max_wait: float
    camera_bracket: str
    camera_latency: float  # s (wall): a camera frame's transport time, subtracted by the elapsed rule
    publish_odom_tf: bool
    publish_field: bool
    map_to_odom: str
    diag_period: float
    stale_warn: float
    stale_error: float
    log_period: float
    topics: dict
    frames: dict  # final frame ids, prefix applied
    sim_port: int = 0  # 0: the first consistent sender's port
    max_jump: int = 250  # cycles
    takeover_after: float = 2.0  # wall s
    max_wheel_speed: float = 54.0  # rad/s
    sim_control: tuple[str, int] | None = None  # raf sim's control channel (the sim/* services); None: off

    @property
    def source(self) -> tuple[str, int] | None:
        """The configured sender (host, port), or None: the first consistent one binds the stream."""
        return (self.sim_host, self.sim_port) if self.sim_host != "*" and self.sim_port else None

    @property
    def max_ticks_per_s(self) -> float:
        return self.max_wheel_speed * self.ticks_per_rev / (2 * math.pi)

    @property
    def camera(self) -> CameraSpec:
        """The camera's mount and intrinsics as set by the parameters."""
        return CameraSpec(self.camera_xyz, self.camera_pitch_down_deg, self.width, self.height, self.fx, self.fy,
                          self.cx, self.cy, self.bottom_up, self.render_fps, self.decimation,
                          roll_deg=self.camera_roll_deg, distortion=self.distortion)

    @property
    def control_period_ms(self) -> int:
        return int(round(self.control_period * 1000))

    def frame(self, key: str) -> str:
        return self.frames[key]

    def marker_frame(self, marker_id: int) -> str:
        return f"{self.frames['marker_prefix']}{marker_id}"

    def flat_params(self) -> dict[str, Any]:
        """``{"udp/port": 9810, ...}``: the tree as flat parameter names (without the ``~``)."""
        out: dict[str, Any] = {}

        def walk(d, prefix):
            for k, v in d.items():
                if isinstance(v, dict):
                    walk(v, f"{prefix}{k}/")
                else:
                    out[f"{prefix}{k}"] = v
        walk(self.params, "")
        return out


def _control(p: dict) -> tuple[str, int] | None:
    """``simulator/control``: ``host:port`` of raf sim's control channel (ros/sim_services.py), "" for none."""
    text = _str(p, ("simulator", "control"), r"|[A-Za-z0-9_.\-]+:\d{1,5}", "host:port of raf sim's control "
                "channel, e.g. 127.0.0.1:9812, or empty for none")
    if not text:
        return None
    host, port = text.rsplit(":", 1)
    if not 0 < int(port) <= 65535:
        raise ConfigError(f"parameter ~simulator/control {text!r}: port must be 1..65535")
    return host, int(port)


def _calibrated(cfg: BridgeConfig, path: str, defaults: dict) -> BridgeConfig:
    """``cfg`` with the camera of a calibration file (raf calibrate), parsed once into the camera object raf
    localize makes of it too (``Calibration.apply``). A camera/* value set to something else than the robot
    file's (``--set camera/cy=240.25``, a launch file's) is a deliberate override and stays."""
    from ..localization.calibration import load_calibration

    try:
        cam = load_calibration(path).apply(cfg.camera)
    except ConfigError as e:
        raise ConfigError(f"parameter ~camera/calibration: {e}") from None
    out = {}
    for key, attr, value in (("xyz", "camera_xyz", tuple(cam.xyz)), ("pitch_down_deg", "camera_pitch_down_deg",
                                                                      cam.pitch_down_deg),
                             ("roll_deg", "camera_roll_deg", cam.roll_deg),
                             ("distortion", "distortion", tuple(cam.distortion)),
                             ("fx", "fx", cam.fx), ("fy", "fy", cam.fy), ("cx", "cx", cam.cx), ("cy", "cy", cam.cy)):
        given = getattr(cfg, attr)
        default = defaults[key]
        unchanged = (list(given) == [float(v) for v in default]) if isinstance(given, tuple) else \
            given == float(default)
        out[attr] = value if unchanged else given
    return replace(cfg, **out)


def load_config(overrides: dict | None = None, robot: RobotSpec | None = None) -> BridgeConfig:
    """Defaults merged with ``overrides`` (nested dict as in config/bridge.yaml), validated."""
    base = default_params(robot)
    p = merge(base, overrides)
    if robot is None and p["robot"] != base["robot"]:
        try:
            base = default_params(load_robot(p["robot"]))
        except FileNotFoundError as e:
            raise ConfigError(f"parameter ~robot: {e}") from None
        p = merge(base, overrides)
    prefix = _str(p, ("frame_prefix",), r"|[A-Za-z_][A-Za-z0-9_/]*[A-Za-z0-9_]", "empty or a frame prefix such "
                  "as robot1 (letters, digits, _ and /, no leading or trailing /)")
    frames = {}
    for k in DEFAULT_FRAMES:
        v = _str(p, ("frames", k), _FRAME, "a frame id (letters, digits, _ and /, no leading /)")
        frames[k] = f"{prefix}/{v}" if prefix and k in ROBOT_FRAMES else v
    topics = {k: _str(p, ("topics", k), _NAME, "a ROS name") for k in DEFAULT_TOPICS}
    period = _real(p, ("geometry", "control_period"), 0.0, 10.0, lo_open=True)
    step = _real(p, ("geometry", "physics_step"), 0.0, period, lo_open=True)
    if abs(period * 1000 - round(period * 1000)) > 1e-6:
        raise ConfigError(f"parameter ~geometry/control_period must be whole milliseconds, got {period!r}")
    cfg = BridgeConfig(
        params=p,
        field=_str(p, ("field",)),
        robot=_str(p, ("robot",)),
        frame_prefix=prefix,
        bind_host=_bind_host(p),
        port=_int(p, ("udp", "port"), 0, 65535),
        max_datagram=_int(p, ("udp", "max_datagram"), 64, 65507),
        sim_host=_host(p, ("simulator", "host"), allow_any=True),
        reply_port=_int(p, ("simulator", "reply_port"), 0, 65535),
        sim_port=_int(p, ("simulator", "port"), 0, 65535),
        sim_control=_control(p),
        max_jump=_int(p, ("stream", "max_jump"), 1, 10 ** 9),
        takeover_after=_real(p, ("stream", "takeover_after"), 0.0),
        max_wheel_speed=_real(p, ("stream", "max_wheel_speed"), 0.0, lo_open=True),
        reorder_window=_int(p, ("stream", "reorder_window"), 1, 10 ** 6),
        restart_confirm=_int(p, ("stream", "restart_confirm"), 1, 1000),
        watchdog_timeout=_real(p, ("watchdog", "timeout"), 0.0, lo_open=True),
        control_period=period,
        physics_step=step,
        wheel_radius=_real(p, ("geometry", "wheel_radius"), 0.0, 10.0, lo_open=True),
        track=_real(p, ("geometry", "track"), 0.0, 10.0, lo_open=True),
        ticks_per_rev=_int(p, ("geometry", "ticks_per_rev"), 1, 10 ** 9),
        slip_var_per_m=_real(p, ("odometry", "slip_var_per_m"), 0.0),
        odometry_track=_real(p, ("odometry", "track"), 0.0, 10.0, lo_open=True),
        lidar_enabled=_bool(p, ("lidar", "enabled")),
        lidar_xyz=_xyz(p, ("lidar", "xyz")),
        lidar_fov_deg=_real(p, ("lidar", "fov_deg"), 0.0, 360.0, lo_open=True),
        lidar_range_min=_real(p, ("lidar", "range_min"), 0.0),
        lidar_range_max=_real(p, ("lidar", "range_max"), 0.0, lo_open=True),
        lidar_period=_real(p, ("lidar", "period"), 0.0, lo_open=True),
        lidar_mode=_str(p, ("lidar", "mode"), allowed=("sweep", "cycle")),
        lidar_update=_str(p, ("lidar", "update"), allowed=("sweep", "per_ray")),
        lidar_ray_timing=_str(p, ("lidar", "ray_timing"), allowed=("rolling", "instant")),
        lidar_self_filter=_bool(p, ("lidar", "self_filter")),
        lidar_self_margin=_real(p, ("lidar", "self_margin"), 0.0, 0.1),
        lidar_delivery_lag=_real(p, ("lidar", "delivery_lag"), 0.0, period),
        camera_enabled=_bool(p, ("camera", "enabled")),
        camera_endpoint=_str(p, ("camera", "endpoint"), r"(tcp|ipc|inproc)://\S+",
                             "a ZMQ endpoint such as tcp://192.168.1.20:9899"),
        camera_xyz=_xyz(p, ("camera", "xyz")),
        camera_pitch_down_deg=_real(p, ("camera", "pitch_down_deg"), -90.0, 90.0),
        camera_roll_deg=_real(p, ("camera", "roll_deg"), -90.0, 90.0),
        distortion=_distortion(p, ("camera", "distortion")),
        width=_int(p, ("camera", "width"), 1, 16384),
        height=_int(p, ("camera", "height"), 1, 16384),
        fx=_real(p, ("camera", "fx"), 0.0, lo_open=True),
        fy=_real(p, ("camera", "fy"), 0.0, lo_open=True),
        cx=_real(p, ("camera", "cx")),
        cy=_real(p, ("camera", "cy")),
        bottom_up=_bool(p, ("camera", "bottom_up")),
        render_fps=_real(p, ("camera", "render_fps"), 0.0, lo_open=True),
        decimation=_int(p, ("camera", "decimation"), 1, 10 ** 6),
        use_grid=_bool(p, ("camera", "use_grid")),
        max_wait=_real(p, ("camera", "max_wait"), 0.0, 1.0),
        camera_bracket=_str(p, ("camera", "bracket"), allowed=("elapsed", "following", "nearest")),
        camera_latency=_real(p, ("camera", "latency"), 0.0, 0.1),
        publish_odom_tf=_bool(p, ("tf", "publish_odom")),
        publish_field=_bool(p, ("tf", "publish_field")),
        map_to_odom=_str(p, ("tf", "map_to_odom"), allowed=("none", "identity", "first_ground_truth")),
        diag_period=_real(p, ("diagnostics", "period"), 0.0, 60.0, lo_open=True),
        stale_warn=_real(p, ("diagnostics", "stale_warn"), 0.0, lo_open=True),
        stale_error=_real(p, ("diagnostics", "stale_error"), 0.0, lo_open=True),
        log_period=_real(p, ("log_period",), 0.0),
        topics=topics,
        frames=frames,
    )
    if cfg.lidar_range_min >= cfg.lidar_range_max:
        raise ConfigError(f"parameter ~lidar/range_min ({cfg.lidar_range_min}) must be below ~lidar/range_max "
                          f"({cfg.lidar_range_max})")
    if cfg.stale_error < cfg.stale_warn:
        raise ConfigError(f"parameter ~diagnostics/stale_error ({cfg.stale_error}) must be >= "
                          f"~diagnostics/stale_warn ({cfg.stale_warn})")
    if not (0 <= cfg.cx <= cfg.width and 0 <= cfg.cy <= cfg.height):
        raise ConfigError(f"parameters ~camera/cx, ~camera/cy ({cfg.cx}, {cfg.cy}) must lie in the "
                          f"{cfg.width}x{cfg.height} image")
    calibration = _str(p, ("camera", "calibration"))
    if calibration:
        cfg = _calibrated(cfg, calibration, base["camera"])
    _check_field(cfg.field)
    return cfg


def _check_field(name: str) -> None:
    from ..field import load_field
    from ..field.loader import FieldError

    try:
        load_field(name)
    except (FieldError, FileNotFoundError) as e:
        raise ConfigError(f"parameter ~field: {e}") from None
