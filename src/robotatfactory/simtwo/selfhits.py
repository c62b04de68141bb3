"""The LIDAR's hits on its own robot: rays whose hit point lies inside the robot's footprint are no obstacles.

Plain Python, no ROS. Frames: ``base_link`` (on the floor between the wheels, x forward, y left) and the
``laser`` frame (at ``xyz`` in ``base_link``, not rotated: SimTwo's ranger2d of simtwo/AGV_lidar.xml).

SimTwo's ranger rays are ODE rays in the scene's one space, each attached to the ranger's body (``Viewer.pas``
853-863 ``CreateOneRaySensor``, 4274 the space; ``nearCallback`` ``Viewer.pas`` 346-410 keeps each ray's
nearest hit): ODE never collides two geoms of one body, so the ranger's own body (the base plate
and the shells attached to it) is not hit, but every other body is, the robot's wheels included (separate
bodies, ``AGV.xml``: radius 0.0325 m, 6 mm thick, centres at y = +/-0.0675 m). With the scan plane at 0.05 m
(the wheels' tops are at 0.065 m) the rays within about +/-23 degrees of +/-90 degrees end on the wheels'
inner faces, 0.065-0.07 m away: about 90 of 360 rays, which ``range_min`` (0.02 m) passes as obstacles.

The footprint is the union of rectangles in ``base_link``: the base plate (``base.size``, centred on x = y =
0) and each wheel's cut by the scan plane (x within the chord ``sqrt(R^2 - (z - R)^2)``, y over the wheel's
width around ``+/-track/2``), each grown by ``margin``. Nothing but the robot can be inside it, so a hit there
is the robot itself. The default margin, 0.009 m, is 5 sigma of the range noise at the wheels (sigma =
0.001524 * exp(1.3103 * 0.07) = 1.7 mm; a noisy wheel hit 3.7 sigma short was seen on the stand-in) and less
than the 0.01 m between the base's front (x = 0.07 m) and the electromagnet's face (x = 0.08 m), so a part
held by the magnet stays outside it.

How a filtered ray is published (REP 117): **NaN**, "an erroneous or invalid measurement". The ray measured
the robot, not the world: it says nothing about obstacles along its bearing (it must not clear space as a
no-return +Inf would) and nothing too close to measure is out there (-Inf, "too close to quantify", would
read as an obstacle at the robot's own edge to a costmap or a safety stop). Consumers that skip non-finite
ranges (``robotatfactory.localization.lidar``) treat those bearings as occluded.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Footprint:
    """Rectangles ``(x_min, x_max, y_min, y_max)`` in ``base_link`` (m): the robot's own outline in the scan."""

    boxes: tuple[tuple[float, float, float, float], ...]

    @classmethod
    def from_robot(cls, robot, scan_z: float | None = None, margin: float = 0.009) -> "Footprint":
        """The base plate and the wheels of a :class:`~robotatfactory.robot.RobotSpec` at the scan height
        ``scan_z`` (default: the LIDAR's mount height), each grown by ``margin`` (m)."""
        z = robot.lidar.xyz[2] if scan_z is None else float(scan_z)
        m = float(margin)
        lx, ly = float(robot.base["size"][0]), float(robot.base["size"][1])
        boxes = [(-lx / 2 - m, lx / 2 + m, -ly / 2 - m, ly / 2 + m)]
        r = float(robot.wheel_radius)
        w = float(robot.wheel.get("width", 0.0))
        dz = z - r  # the wheels' axles are at height r
        if abs(dz) < r:
            half = math.sqrt(r * r - dz * dz)
            for side in (1, -1):
                yc = side * robot.track / 2
                boxes.append((-half - m, half + m, yc - w / 2 - m, yc + w / 2 + m))
        return cls(tuple(boxes))

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """True where (x, y) (``base_link``, m) lies inside the footprint."""
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        inside = np.zeros(np.broadcast(x, y).shape, dtype=bool)
        for x0, x1, y0, y1 in self.boxes:
            inside |= (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
        return inside

    @property
    def reach(self) -> float:
        """Distance (m) from base_link's origin to the farthest corner: no self-hit lies farther."""
        return max(math.hypot(max(abs(a), abs(b)), max(abs(c), abs(d))) for a, b, c, d in self.boxes)


class SelfFilter:
    """Replaces the ranges that end inside the robot's footprint by NaN and counts them.

    ``angles``: the rays' directions in the laser frame (rad); ``laser_xy``: the laser's origin in base_link.
    """

    def __init__(self, footprint: Footprint, angles: np.ndarray, laser_xy=(0.0, 0.0)):
        self.footprint = footprint
        a = np.asarray(angles, dtype=float)
        self.n = len(a)
        self._c, self._s = np.cos(a), np.sin(a)
        self.lx, self.ly = float(laser_xy[0]), float(laser_xy[1])
        self._reach = footprint.reach + math.hypot(self.lx, self.ly)
        self.filtered_total = 0  # rays replaced since construction
        self.scans = 0

    def mask(self, ranges: np.ndarray) -> np.ndarray:
        """True for the rays whose (finite, non-negative) range ends inside the footprint."""
        r = np.asarray(ranges, dtype=float)
        with np.errstate(invalid="ignore"):
            near = np.isfinite(r) & (r >= 0) & (r <= self._reach)
        out = np.zeros(len(r), dtype=bool)
        if near.any():
            i = np.flatnonzero(near)
            out[i] = self.footprint.contains(self.lx + r[i] * self._c[i], self.ly + r[i] * self._s[i])
        return out

    def apply(self, ranges: np.ndarray) -> tuple[np.ndarray, int]:
        """(a copy of ``ranges`` with the self-hits set to NaN, how many there were)."""
        r = np.array(ranges, dtype=float)
        if len(r) != self.n:
            raise ValueError(f"{len(r)} rays, expected {self.n}")
        m = self.mask(r)
        k = int(m.sum())
        r[m] = np.nan
        self.filtered_total += k
        self.scans += 1
        return r, k
