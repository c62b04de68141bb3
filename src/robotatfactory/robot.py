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

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1.0]])

    def base_to_link(self) -> np.ndarray:
        """4x4 transform base_link <- camera_link (x forward, pitched down by ``pitch_down_deg``)."""
        p = math.radians(self.pitch_down_deg)
        c, s = math.cos(p), math.sin(p)
        T = np.eye(4)
        T[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
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
        contact=raw["contact"], electromagnet=raw["electromagnet"],
    )
