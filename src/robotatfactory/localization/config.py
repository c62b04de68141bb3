"""Settings of the localization (``config/localization.yaml``): detector, pose estimators, EKF, LIDAR beacons,
LIDAR scan matching and the ROS node's wiring. Plain Python (no ROS): the node passes its private parameters (a
nested dict) to :func:`from_dict`; ``raf localize``, the bench and the experiment load the YAML file with
:func:`load_config`.
Unknown keys and bad values raise :class:`~robotatfactory.errors.ConfigError` naming them.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, fields
from dataclasses import field as dc_field
from pathlib import Path

from ..errors import ConfigError
from ..settings import deep_update
from ..settings import read_yaml as _read_yaml
from .detect import DetectorConfig
from .ekf import EkfConfig
from .lidar import BeaconConfig
from .markerpose import PoseConfig
from .scanmatch import ScanMatchConfig

ROOT = Path(__file__).resolve().parents[3]
DEFAULT_FILE = ROOT / "config" / "localization.yaml"

DEFAULT_TOPICS = {
    "image": "camera/image_raw",
    "camera_info": "camera/camera_info",
    "odom": "odom",
    "scan": "scan",
    "markers": "aruco/markers",
    "marker_poses": "aruco/poses",
    "debug_image": "aruco/debug_image",
    "camera_pose": "camera_pose",
    "fixes": "aruco/fixes",
    "pose": "pose",
    "diagnostics": "/diagnostics",
}
DEFAULT_FRAMES = {"map": "map", "odom": "odom", "base_link": "base_link", "camera_optical": "camera_optical",
                  "laser": "laser"}


@dataclass
class NodeConfig:
    """The ROS node's behaviour (``node:`` in the YAML file)."""

    camera_pose_method: str = "closest"  # the paper's method on camera_pose (closest | closest_checked)
    filter_method: str = "planar"  # camera fixes the EKF uses (planar | all_pnp | closest_checked)
    all_methods: bool = False  # also run all_pnp/closest_checked every frame (costs time; for experiments)
    use_prior: bool = True  # seed the planar fit with the EKF's pose
    use_camera_info: bool = True  # take K from camera_info (else the robot file's)
    use_lidar: bool = True  # LIDAR beacon updates (only if beacons are seen)
    initial_pose: str = "none"  # none: wait for a confident camera fix | start: the field's start pose
    initial_sigma_xy: float = 0.05
    initial_sigma_theta_deg: float = 10.0
    publish_tf: bool = True  # map -> odom (REP 105)
    tf_future_s: float = 0.0  # post-date map -> odom (s); 0 = stamped with the odometry time
    debug_image: bool = True  # only drawn while someone subscribes
    debug_axis_m: float = 0.03  # length of the drawn marker axes
    diagnostics_period: float = 1.0
    log_period: float = 5.0  # s between repeated warnings of the same kind
    max_image_age_s: float = 1.0  # frames older than the filter's history are dropped anyway

    def check(self) -> None:
        if self.camera_pose_method not in ("closest", "closest_checked"):
            raise ConfigError(f"node/camera_pose_method must be closest or closest_checked, "
                              f"not {self.camera_pose_method!r}")
        if self.filter_method not in ("planar", "all_pnp", "closest_checked"):
            raise ConfigError(f"node/filter_method must be planar, all_pnp or closest_checked, "
                              f"not {self.filter_method!r}")
        if self.initial_pose not in ("none", "start"):
            raise ConfigError(f"node/initial_pose must be none or start, not {self.initial_pose!r}")
        for k in ("diagnostics_period", "log_period", "initial_sigma_xy", "initial_sigma_theta_deg"):
            if not float(getattr(self, k)) > 0:
                raise ConfigError(f"node/{k} must be > 0, got {getattr(self, k)!r}")

    def methods(self) -> tuple[str, ...]:
        if self.all_methods:
            return ("closest", "closest_checked", "all_pnp", "planar")
        return tuple(dict.fromkeys((self.camera_pose_method, self.filter_method)))


@dataclass
class LocalizationConfig:
    field: str = "rules2026"
    robot: str = "simtwo"
    frame_prefix: str = ""
    calibration: str = ""  # camera calibration YAML (raf calibrate): overrides the robot file's camera and camera_info
    detector: DetectorConfig = dc_field(default_factory=DetectorConfig)
    pose: PoseConfig = dc_field(default_factory=PoseConfig)
    ekf: EkfConfig = dc_field(default_factory=EkfConfig)
    beacons: BeaconConfig = dc_field(default_factory=BeaconConfig)
    scan_match: ScanMatchConfig = dc_field(default_factory=ScanMatchConfig)
    node: NodeConfig = dc_field(default_factory=NodeConfig)
    topics: dict = dc_field(default_factory=lambda: dict(DEFAULT_TOPICS))
    frames: dict = dc_field(default_factory=lambda: dict(DEFAULT_FRAMES))

    def frame(self, name: str) -> str:
        """A frame id with the robot prefix applied (``map`` is never prefixed)."""
        f = self.frames[name]
        if name != "map" and self.frame_prefix:
            return f"{self.frame_prefix.strip('/')}/{f}"
        return f


def _section(cls, d, name):
    if d is None:
        return cls()
    if not isinstance(d, dict):
        raise ConfigError(f"localization setting {name!r} is a section, got {d!r}")
    known = {f.name for f in fields(cls)}
    bad = sorted(set(d) - known - ({"extra"} if cls is DetectorConfig else set()))
    if bad and cls is not DetectorConfig:
        raise ConfigError(f"unknown setting(s) {', '.join(f'{name}/{b}' for b in bad)}; known: {sorted(known)}")
    if cls is DetectorConfig:
        return DetectorConfig.from_dict(d)
    try:
        obj = cls(**d)
    except TypeError as e:
        raise ConfigError(f"section {name}: {e}") from None
    for f in fields(cls):
        v = getattr(obj, f.name)
        default = getattr(cls(), f.name)
        if isinstance(default, bool) and not isinstance(v, bool):
            raise ConfigError(f"setting {name}/{f.name} must be true or false, got {v!r}")
        if isinstance(default, (int, float)) and not isinstance(default, bool):
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"setting {name}/{f.name} must be a number, got {v!r}")
        if isinstance(default, str) and not isinstance(v, str):
            raise ConfigError(f"setting {name}/{f.name} must be a string, got {v!r}")
    return obj


def from_dict(d: dict | None) -> LocalizationConfig:
    d = copy.deepcopy(d or {})
    if not isinstance(d, dict):
        raise ConfigError(f"localization settings must be a mapping, got {type(d).__name__}")
    known = {f.name for f in fields(LocalizationConfig)}
    bad = sorted(set(d) - known)
    if bad:
        raise ConfigError(f"unknown localization setting(s) {bad}; known: {sorted(known)}")
    cfg = LocalizationConfig(
        field=str(d.get("field", "rules2026")), robot=str(d.get("robot", "simtwo")),
        frame_prefix=str(d.get("frame_prefix", "") or ""),
        calibration=str(d.get("calibration", "") or ""),
        detector=_section(DetectorConfig, d.get("detector"), "detector"),
        pose=_section(PoseConfig, d.get("pose"), "pose"),
        ekf=_section(EkfConfig, d.get("ekf"), "ekf"),
        beacons=_section(BeaconConfig, d.get("beacons"), "beacons"),
        scan_match=_section(ScanMatchConfig, d.get("scan_match"), "scan_match"),
        node=_section(NodeConfig, d.get("node"), "node"),
    )
    for key, defaults, target in (("topics", DEFAULT_TOPICS, cfg.topics), ("frames", DEFAULT_FRAMES, cfg.frames)):
        sec = d.get(key) or {}
        if not isinstance(sec, dict):
            raise ConfigError(f"localization setting {key!r} is a section, got {sec!r}")
        bad = sorted(set(sec) - set(defaults))
        if bad:
            raise ConfigError(f"unknown {key} {bad}; known: {sorted(defaults)}")
        for k, v in sec.items():
            if not isinstance(v, str) or not v:
                raise ConfigError(f"{key}/{k} must be a non-empty string, got {v!r}")
            target[k] = v
    cfg.node.check()
    cfg.scan_match.check()
    if cfg.calibration:
        from .calibration import load_calibration

        load_calibration(cfg.calibration)
    return cfg


def robot_for(cfg: LocalizationConfig):
    """The robot spec the localization uses: ``cfg.robot`` with the camera of ``cfg.calibration`` if set."""
    from ..robot import load_robot
    from .calibration import calibrated_robot

    try:
        robot = load_robot(cfg.robot)
    except FileNotFoundError as e:
        raise ConfigError(f"localization setting robot: {e}") from None
    return calibrated_robot(robot, cfg.calibration) if cfg.calibration else robot


def read_yaml(path: str | Path) -> dict:
    return _read_yaml(path, "localization config")


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> LocalizationConfig:
    """Defaults, then ``config/localization.yaml`` (or ``path``), then ``overrides``."""
    d: dict = {}
    if path is not None:
        d = read_yaml(path)
    elif DEFAULT_FILE.is_file():
        d = read_yaml(DEFAULT_FILE)
    if overrides:
        deep_update(d, overrides)
    return from_dict(d)
