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

from .settings import spec


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

    xyz: tuple[float, float, float] = spec("m, camera_link's origin in base_link [x, y, z]", size=(3, 3),
                                           items=float)
    pitch_down_deg: float = spec("deg: camera_link is base_link pitched down by this", lo=-90.0, hi=90.0)
    width: int = spec("px, the image's width", lo=1, hi=16384)
    height: int = spec("px, the image's height", lo=1, hi=16384)
    fx: float = spec("px, focal length along x (GLScene focal length 30 at 96 DPI: 226.8)", lo=0.0, lo_open=True)
    fy: float = spec("px, focal length along y", lo=0.0, lo_open=True)
    cx: float = spec("px, principal point's x, OpenCV convention (pixel centres at integers: 319.5 is the "
                     "middle of 640)")
    cy: float = spec("px, principal point's y")
    bottom_up: bool = spec("rows arrive in OpenGL order (row 0 = bottom): flip them")
    render_fps: float = spec("the simulator's render clock, ticks per WALL second (SimTwo's GUI: 60)", lo=0.0,
                             lo_open=True)
    decimation: int = spec("one published frame every this many renders", lo=1, hi=10 ** 6)
    roll_deg: float = spec("deg, then rolled about camera_link's x (the optical axis), right-handed",
                           default=0.0, lo=-90.0, hi=90.0)
    distortion: tuple[float, float, float, float, float] = spec(
        "OpenCV k1, k2, p1, p2, k3 (ROS plumb_bob, CameraInfo D); zeros: an ideal pinhole (SimTwo's GLScene)",
        default=(0.0, 0.0, 0.0, 0.0, 0.0), size=(1, 5), items=float)

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
    xyz: tuple[float, float, float] = spec("m, base_link -> laser [x, y, z]", size=(3, 3), items=float)
    rays: int = spec("rays per sweep", lo=1)
    fov_deg: float = spec("deg, the field of view: N rays from -fov/2 to +fov/2, step fov/(N-1) (SimTwo's "
                          "ranger2d)", lo=0.0, hi=360.0, lo_open=True)
    range_max: float = spec("m, the longest range", lo=0.0, lo_open=True)
    range_min: float = spec("m, the shortest range", lo=0.0)
    period: float = spec("s, one sweep: LaserScan.scan_time (SimTwo: rays measured in turn, delivered all at "
                         "once)", lo=0.0, lo_open=True)
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
    control_period: float = spec("s, SimTwo's script period (Tms advances by this per cycle): whole "
                                 "milliseconds", lo=0.0, hi=10.0, lo_open=True)
    physics_step: float = spec("s, SimTwo's physics step (the LIDAR's ray schedule); at most control_period",
                               lo=0.0, hi=10.0, lo_open=True)
    wheel_radius: float = spec("m", lo=0.0, hi=10.0, lo_open=True)
    track: float = spec("m, the wheels' separation (TF)", lo=0.0, hi=10.0, lo_open=True)
    ticks_per_rev: int = spec("encoder ticks per wheel revolution", lo=1, hi=10 ** 9)
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
