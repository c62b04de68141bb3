"""The robot's parameters as data (``data/robot_simtwo.json``): geometry, motors, sensors' mounts.

Shared by the stand-in simulator, the bridge (odometry, static TFs, camera_info) and localization, so
that the three agree. ``base_link`` is on the floor midway between the wheels (x forward, y left, z up).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class CameraSpec:
    """The camera: mount on ``base_link`` and pinhole intrinsics with OpenCV's distortion model.

    ``xyz`` (m) is camera_link's origin in base_link; camera_link is base_link pitched down by
    ``pitch_down_deg`` (about base_link's y), then rolled by ``roll_deg`` about its own x (the optical axis;
    right-handed: positive raises the camera's left side and lowers its right). ``fx, fy, cx, cy`` in pixels with pixel
    centres at integers (``cx = 319.5`` is the centre of a 640-wide image). ``distortion`` is OpenCV's
    (k1, k2, p1, p2, k3) (ROS's ``plumb_bob``); zeros for SimTwo's GLScene camera, an ideal pinhole.
    ``raf calibrate`` estimates all but the image size and the timing (docs/calibration.md).
    """

    xyz: tuple[float, float, float]
    pitch_down_deg: float
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    bottom_up: bool
    render_fps: float
    decimation: int
    roll_deg: float = 0.0
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "xyz", tuple(float(v) for v in self.xyz))
        d = tuple(float(v) for v in (self.distortion or ()))
        if len(d) > 5 or not all(math.isfinite(v) for v in d):
            raise ValueError(f"camera distortion must be up to five finite numbers (k1, k2, p1, p2, k3), "
                             f"got {self.distortion!r}")
        object.__setattr__(self, "distortion", d + (0.0,) * (5 - len(d)))

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    @property
    def D(self) -> np.ndarray:
        """OpenCV distortion coefficients (k1, k2, p1, p2, k3) as a float64 array of 5."""
        return np.array(self.distortion, dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(v != 0.0 for v in self.distortion)

    def base_to_link(self) -> np.ndarray:
        """4x4 transform base_link <- camera_link (x forward, pitched down by ``pitch_down_deg``, then rolled
        by ``roll_deg`` about its own x axis)."""
        p, r = math.radians(self.pitch_down_deg), math.radians(self.roll_deg)
        c, s = math.cos(p), math.sin(p)
        cr, sr = math.cos(r), math.sin(r)
        Ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
        T = np.eye(4)
        T[:3, :3] = Ry @ Rx
        T[:3, 3] = self.xyz
        return T

    @staticmethod
    def link_to_optical() -> np.ndarray:
        """4x4 rotation camera_link <- camera_optical (optical: x right, y down, z forward; REP 103)."""
        T = np.eye(4)
        T[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]
        return T

    def base_to_optical(self) -> np.ndarray:
        """4x4 transform base_link <- camera_optical."""
        return self.base_to_link() @ self.link_to_optical()


@dataclass(frozen=True)
class LidarSpec:
    xyz: tuple[float, float, float]
    rays: int
    fov_deg: float
    range_max: float
    range_min: float
    period: float
    noise_a: float
    noise_b: float

    def angles(self) -> np.ndarray:
        """Ray angles (rad) in the laser frame, SimTwo's ranger2d: -fov/2 .. +fov/2, step fov/(N-1)."""
        fov = math.radians(self.fov_deg)
        if self.rays == 1:
            return np.zeros(1)
        return -fov / 2 + np.arange(self.rays) * fov / (self.rays - 1)

    def noise_sigma(self, d: np.ndarray | float):
        return self.noise_a * np.exp(self.noise_b * np.asarray(d))


@dataclass(frozen=True)
class RobotSpec:
    name: str
    control_period: float
    physics_step: float
    wheel_radius: float
    track: float
    ticks_per_rev: int
    base: dict
    wheel: dict
    caster: dict
    motor: dict
    speed_controller: dict
    camera: CameraSpec
    lidar: LidarSpec
    contact: dict
    electromagnet: dict
    simtwo_pid: dict | None = None  # SimTwo's own speed controller's gains (CalcPID), see data/robot_simtwo.json
    #: the track dead reckoning turns with (m): the wheels' effective separation, measured; None: ``track``
    odometry_track_m: float | None = None

    @property
    def odometry_track(self) -> float:
        """The track odometry integrates turns with: ``odometry_track_m`` when the robot file measured one
        (SimTwo's robot turns about a shorter track than its wheels' spacing: docs/simtwo.md), else ``track``."""
        return float(self.odometry_track_m) if self.odometry_track_m else self.track

    @property
    def metres_per_tick(self) -> float:
        return 2 * math.pi * self.wheel_radius / self.ticks_per_rev

    def wheel_speeds(self, v: float, w: float) -> tuple[float, float]:
        """Body (V, W) to wheel angular speeds (left, right) in rad/s."""
        return ((v - w * self.track / 2) / self.wheel_radius, (v + w * self.track / 2) / self.wheel_radius)

    def body_speeds(self, wl: float, wr: float) -> tuple[float, float]:
        """Wheel angular speeds (rad/s) to body (V, W)."""
        r = self.wheel_radius
        return (r * (wl + wr) / 2, r * (wr - wl) / self.track)


def load_robot(name_or_path: str = "simtwo") -> RobotSpec:
    p = Path(name_or_path)
    if p.suffix == ".json" and p.exists():
        raw = json.loads(p.read_text())
    else:
        res = resources.files("robotatfactory") / "data" / f"robot_{name_or_path}.json"
        if not res.is_file():
            raise FileNotFoundError(f"unknown robot {name_or_path!r} (shipped: simtwo) and no such .json file")
        raw = json.loads(res.read_text())
    cam = {k: v for k, v in raw["camera"].items()}
    cam["xyz"] = tuple(cam["xyz"])
    lid = dict(raw["lidar"])
    lid["xyz"] = tuple(lid["xyz"])
    return RobotSpec(
        name=raw["name"], control_period=raw["control_period"], physics_step=raw["physics_step"],
        wheel_radius=raw["wheel_radius"], track=raw["track"], ticks_per_rev=raw["ticks_per_rev"],
        base=raw["base"], wheel=raw["wheel"], caster=raw["caster"], motor=raw["motor"],
        speed_controller=raw["speed_controller"], camera=CameraSpec(**cam), lidar=LidarSpec(**lid),
        contact=raw["contact"], electromagnet=raw["electromagnet"], simtwo_pid=raw.get("simtwo_pid"),
        odometry_track_m=raw.get("odometry_track"),
    )
