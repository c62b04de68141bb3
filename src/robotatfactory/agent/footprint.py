"""The robot's outline and the docking geometry of a slot (no ROS, no simulator internals).

The outline is read from the robot file (``data/robot_simtwo.json``) as rectangles in base_link
(x forward, y left, metres): the base box, the wheels (``track`` +- half a tyre width, as long as a wheel's
diameter) and the electromagnet (1 cm deep, 2 cm wide, its face at ``electromagnet.x``). A carried part
adds its body in front of the magnet. ``radius`` is the circle around base_link that holds the outline:
the robot may turn in place wherever that circle is clear.

Docking: a part's plate faces ``slot.facing``; the robot faces the plate (heading ``facing + pi``) with its
magnet face ``gap`` metres from the plate, so base_link is ``depth/2 + plate thickness + magnet x + gap``
from the slot centre along ``facing``. A carried part hangs on the magnet with its centre at the same
distance (``gap`` = the magnet's hold gap), so the place pose of a slot equals its dock pose.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..localization.geometry import wrap_angle as wrap  # (-pi, pi], the project's one angle wrap

PLATE_THICKNESS = 0.002  # m the ferromagnetic plate stands proud of the part's front face
MAGNET_DEPTH = 0.01  # m the electromagnet's housing, behind its face
MAGNET_WIDTH = 0.02  # m
HOLD_GAP = 0.0005  # m between the magnet face and a held plate


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle in base_link: x in [x0, x1], y in [y0, y1] (m)."""

    x0: float
    x1: float
    y0: float
    y1: float

    def corners(self) -> np.ndarray:
        return np.array([[self.x0, self.y0], [self.x1, self.y0], [self.x1, self.y1], [self.x0, self.y1]])


@dataclass(frozen=True)
class Footprint:
    """The robot's outline as rectangles in base_link (m)."""

    rects: tuple[Rect, ...]

    # (derived once per outline: the planner asks for them thousands of times a decision)
    @cached_property
    def radius(self) -> float:
        """The largest distance (m) from base_link to the outline: the turning-in-place circle."""
        return max(float(np.hypot(*c)) for r in self.rects for c in r.corners())

    @cached_property
    def inner(self) -> float:
        """The largest distance (m) around base_link that the outline covers in every direction (the nearest edge
        of a rectangle holding base_link): a point closer than this to anything means the outline touches it."""
        return max((min(-r.x0, r.x1, -r.y0, r.y1) for r in self.rects if r.x0 <= 0 <= r.x1 and r.y0 <= 0 <= r.y1),
                   default=0.0)

    @cached_property
    def front(self) -> float:
        return max(r.x1 for r in self.rects)

    @cached_property
    def back(self) -> float:
        return min(r.x0 for r in self.rects)

    @cached_property
    def _corners(self) -> np.ndarray:
        """Every rectangle's corners, (rectangles, 4, 2), base_link."""
        return np.array([r.corners() for r in self.rects], dtype=float).reshape(-1, 4, 2)

    def polygons(self, x: float, y: float, theta: float) -> list[np.ndarray]:
        """Each rectangle's four corners (4x2, field frame) with base_link at (x, y, theta)."""
        return list(self.corners_at(x, y, theta))

    def corners_at(self, x: float, y: float, theta: float) -> np.ndarray:
        """:meth:`polygons` as one array (rectangles, 4, 2)."""
        c, s = math.cos(theta), math.sin(theta)
        R = np.array([[c, s], [-s, c]])  # row vectors: p_world = p_local @ R + t
        return self._corners @ R + (x, y)

    def corners_at_poses(self, x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """:meth:`corners_at` for many poses at once (arrays of x, y and heading): (poses, rectangles, 4, 2)."""
        c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
        lx, ly = self._corners[None, ..., 0], self._corners[None, ..., 1]
        return np.stack((lx * c - ly * s + x[:, None, None], lx * s + ly * c + y[:, None, None]), axis=-1)

    def inflated(self, margin: float) -> Footprint:
        """Every rectangle grown by ``margin`` m on each side (a safety margin for exact checks)."""
        m = float(margin)
        return Footprint(tuple(Rect(r.x0 - m, r.x1 + m, r.y0 - m, r.y1 + m) for r in self.rects))

    def with_part(self, depth: float, width: float, magnet_x: float) -> Footprint:
        """The outline while carrying a part (``depth`` x ``width`` m) on the magnet whose face is at x
        ``magnet_x``."""
        x0 = magnet_x + HOLD_GAP
        return Footprint(self.rects + (Rect(x0, x0 + PLATE_THICKNESS + depth, -width / 2, width / 2),))


def robot_footprint(robot) -> Footprint:
    """The outline of a :class:`robotatfactory.robot.RobotSpec` (see the module docstring)."""
    bx, by = float(robot.base["size"][0]), float(robot.base["size"][1])
    r = float(robot.wheel_radius)
    wy = float(robot.track) / 2 + float(robot.wheel.get("width", 0.02)) / 2
    mx = float(robot.electromagnet["x"])
    return Footprint((Rect(-bx / 2, bx / 2, -by / 2, by / 2), Rect(-r, r, -wy, wy),
                      Rect(mx - MAGNET_DEPTH, mx, -MAGNET_WIDTH / 2, MAGNET_WIDTH / 2)))


def carrying_footprint(robot, part) -> Footprint:
    """The outline while the magnet holds a part of the field's :class:`PartSpec`."""
    return robot_footprint(robot).with_part(float(part.depth), float(part.width), float(robot.electromagnet["x"]))


def dock_distance(robot, part, gap: float = 0.003) -> float:
    """Distance (m) from a slot centre to base_link when the magnet face is ``gap`` m from the plate."""
    return float(part.depth) / 2 + PLATE_THICKNESS + float(robot.electromagnet["x"]) + gap


def pose_in_front(slot, distance: float) -> tuple[float, float, float]:
    """base_link pose (x, y, theta) ``distance`` m in front of ``slot``'s plate, facing the plate."""
    f = float(slot.facing)
    x = slot.xy[0] + distance * math.cos(f)
    y = slot.xy[1] + distance * math.sin(f)
    return (x, y, wrap(f + math.pi))

