"""The localization's settings: one typed object (:class:`LocalizationConfig`) for the estimators, the filter
and the ROS node.

Every setting has its default, meaning and allowed values once, in the class where it is used: the detector's
in :class:`~.detect.DetectorConfig` (``detector.*``), the pose estimators' in :class:`~.markerpose.PoseConfig`
(``pose.*``), the EKF's in :class:`~.ekf.EkfConfig` (``ekf.*``), the LIDAR beacons' in
:class:`~.lidar.BeaconConfig` (``beacons.*``), the scan matching's in :class:`~.scanmatch.ScanMatchConfig`
(``scan_match.*``), the node's here (``node.*``, ``topics.*``, ``frames.*``). One validation,
:func:`robotatfactory.settings.build`, fills it from a nested mapping: ``raf localize --config FILE --set
ekf.history_s=2`` (:func:`load_config`), the node's ROS parameters (``~ekf/history_s`` on ROS 1,
``ekf.history_s`` on ROS 2; :func:`from_dict`), the competition experiment's ``--localize``; an unknown name or a
bad value is a :class:`~robotatfactory.errors.ConfigError` naming the setting's path and what it allows.
``config/localization.yaml`` lists them all with their defaults (generated: :data:`HEADER`). Plain Python (no
ROS).
"""
from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

from ..errors import ConfigError
from ..field import DEFAULT_FIELD
from ..pace import PaceSettings
from ..settings import build, deep_update, section, setting
from ..settings import read_yaml as _read_yaml
from .detect import DetectorConfig
from .ekf import EkfConfig
from .lidar import BeaconConfig
from .markerpose import PoseConfig
from .scanmatch import ScanMatchConfig

ROOT = Path(__file__).resolve().parents[3]
DEFAULT_FILE = ROOT / "config" / "localization.yaml"

#: the camera fixes the node can publish on camera_pose / give the EKF (:data:`.pipeline.METHODS`)
CAMERA_POSE_METHODS = ("closest", "closest_checked")
FILTER_METHODS = ("planar", "all_pnp", "closest_checked")


@dataclass(frozen=True)
class NodeConfig:
    """The ROS node's behaviour (``node.*``)."""

    camera_pose_method: str = setting("closest", "camera_pose: the paper's method (closest) or with the mount "
                                                 "check (closest_checked)", choices=CAMERA_POSE_METHODS)
    filter_method: str = setting("planar", "the camera fixes the EKF uses: planar | all_pnp | closest_checked",
                                 choices=FILTER_METHODS)
    all_methods: bool = setting(False, "also compute every method each frame on aruco/fixes/<method> (costs time; "
                                       "for experiments)")
    use_prior: bool = setting(True, "seed the planar fit with the EKF's pose")
    use_camera_info: bool = setting(True, "camera matrix from camera_info (else the robot file's; a calibration "
                                          "file takes precedence over both)")
    use_lidar: bool = setting(True, "LIDAR beacon updates (when the field has beacons)")
    initial_pose: str = setting("none", "none: wait for a confident camera fix; start: the field's start pose",
                                choices=("none", "start"))
    initial_sigma_xy: float = setting(0.05, "m, the position sigma of the filter started at the start pose",
                                      lo=0.0, lo_open=True)
    initial_sigma_theta_deg: float = setting(10.0, "deg, its heading sigma", lo=0.0, hi=180.0, lo_open=True)
    publish_tf: bool = setting(True, "publish map -> odom (REP 105)")
    tf_future_s: float = setting(0.0, "s map -> odom is post-dated by (0: stamped with the odometry's time)",
                                 lo=0.0)
    debug_image: bool = setting(True, "draw aruco/debug_image (only while someone subscribes)")
    debug_axis_m: float = setting(0.03, "m, the length of the marker axes drawn on the debug image", lo=0.0)
    diagnostics_period: float = setting(1.0, "s of wall time between /diagnostics reports", lo=0.0, lo_open=True)
    log_period: float = setting(5.0, "s between repeated warnings of the same kind", lo=0.0, lo_open=True)

    def methods(self) -> tuple[str, ...]:
        if self.all_methods:
            return ("closest", "closest_checked", "all_pnp", "planar")
        return tuple(dict.fromkeys((self.camera_pose_method, self.filter_method)))


def _names_check(obj, where: str) -> None:
    """Topic and frame names: none empty."""
    for f in fields(obj):
        if not getattr(obj, f.name).strip("/"):
            raise ConfigError(f"setting {where}.{f.name} must be a name, got {getattr(obj, f.name)!r}")


@dataclass(frozen=True)
class Topics:
    """The node's topics (``topics.*``; relative names resolve in the node's namespace)."""

    image: str = setting("camera/image_raw", "in: sensor_msgs/Image from the bridge's camera")
    camera_info: str = setting("camera/camera_info", "in: sensor_msgs/CameraInfo (K, D)")
    odom: str = setting("odom", "in: nav_msgs/Odometry, base_link in odom")
    scan: str = setting("scan", "in: sensor_msgs/LaserScan (beacons, scan matching)")
    magnet: str = setting("electromagnet", "in: std_msgs/Bool, the robot's own command to its electromagnet (the "
                                           "agent's): while on, the EKF turns with the carrying process noise")
    markers: str = setting("aruco/markers", "out: visualization_msgs/MarkerArray, the detected markers (in "
                                            "camera_optical) with their IDs")
    marker_poses: str = setting("aruco/poses", "out: geometry_msgs/PoseArray, the same poses")
    debug_image: str = setting("aruco/debug_image", "out: the detections drawn (only while subscribed)")
    camera_pose: str = setting("camera_pose", "out: the paper's method, camera_optical in map")
    fixes: str = setting("aruco/fixes", "out: <this>/<method>, base_link in map from each method computed")
    pose: str = setting("pose", "out: the EKF's pose, base_link in map")
    diagnostics: str = setting("/diagnostics", "out: diagnostic_msgs/DiagnosticArray")

    def check(self) -> None:
        _names_check(self, "topics")


@dataclass(frozen=True)
class Frames:
    """The frames (``frames.*``; all but ``map`` get ``frame_prefix``)."""

    map: str = setting("map", "the field's frame (never prefixed)")
    odom: str = setting("odom", "odometry's frame")
    base_link: str = setting("base_link", "the robot, on the floor between the wheels")
    camera_optical: str = setting("camera_optical", "the camera's optical frame (z forward, x right)")
    laser: str = setting("laser", "the LIDAR's frame")

    def check(self) -> None:
        _names_check(self, "frames")


@dataclass(frozen=True)
class LocalizationConfig:
    """Everything the localization and its node can be told."""

    field: str = setting(DEFAULT_FIELD, "competition map: a shipped field's name or a field .json")
    robot: str = setting("simtwo", "robot file name or path: camera mount and intrinsics, track, LIDAR mount")
    frame_prefix: str = setting("", "robot1 makes robot1/odom, robot1/base_link, ... (map is never prefixed)")
    calibration: str = setting("", "camera calibration YAML from raf calibrate (empty: none): overrides the robot "
                                   "file's camera and camera_info")
    detector: DetectorConfig = section(DetectorConfig, "cv2.aruco.ArucoDetector")
    pose: PoseConfig = section(PoseConfig, "the pose estimators (camera fixes)")
    ekf: EkfConfig = section(EkfConfig, "the EKF")
    beacons: BeaconConfig = section(BeaconConfig, "LIDAR beacons (cylinders at the field's beacon positions)")
    scan_match: ScanMatchConfig = section(ScanMatchConfig, "the LIDAR scan matched to the field's walls and ribs: "
                                                           "a pose fix for the EKF")
    node: NodeConfig = section(NodeConfig, "the ROS node's behaviour")
    pace: PaceSettings = section(PaceSettings, "pacing by simulation time: the inputs of each paced frame (odom, "
                                               "scans, images) run in stamp order once the bridge's and the "
                                               "camera's paces are in, then the pose and the pace")
    topics: Topics = section(Topics, "the node's topics")
    frames: Frames = section(Frames, "the node's frames")

    def check(self) -> None:
        """The calibration file, read now (a missing or bad one is an error before the node starts)."""
        if self.calibration:
            from .calibration import load_calibration

            load_calibration(self.calibration)

    def frame(self, name: str) -> str:
        """A frame id with the robot prefix applied (``map`` is never prefixed)."""
        f = getattr(self.frames, name)
        if name != "map" and self.frame_prefix:
            return f"{self.frame_prefix.strip('/')}/{f}"
        return f


HEADER = """The localization's settings (raf localize --config FILE; the node's ROS parameters), every one with its
default. GENERATED from src/robotatfactory/localization/ by `raf localize --print-params --defaults >
config/localization.yaml`: edit the settings there (LocalizationConfig and its sections), then regenerate
(tests/test_localization_config.py fails while this one is out of date). docs/localization.md says what each
part does."""


def from_dict(d: dict | None) -> LocalizationConfig:
    """:class:`LocalizationConfig` from a nested mapping (what it lacks keeps its default), validated."""
    return build(LocalizationConfig, d)


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
    """The defaults, then the YAML file ``path`` (if given), then ``overrides``, validated."""
    d: dict = read_yaml(path) if path is not None else {}
    if overrides:
        deep_update(d, overrides)
    return from_dict(d)
