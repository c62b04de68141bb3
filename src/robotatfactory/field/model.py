"""Typed objects of the competition map. Plain data: no I/O here (see :mod:`.loader`)."""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

MarkerKind = Literal["floor", "wall"]
SlotRole = Literal["store", "input", "output"]
Zone = Literal["incoming", "outgoing", "machine_A", "machine_B"]

# OpenCV's corner order in the marker frame (x right, y towards the top edge, z out of the face),
# as multiples of the side length: top-left, top-right, bottom-right, bottom-left.
CORNER_UNITS = np.array([[-0.5, 0.5, 0.0], [0.5, 0.5, 0.0], [0.5, -0.5, 0.0], [-0.5, -0.5, 0.0]])


@dataclass(frozen=True)
class Marker:
    """An ArUco marker on the field. ``pose`` maps marker-frame points to world points."""

    id: int
    kind: MarkerKind
    size: float
    pose: np.ndarray = field(repr=False)  # 4x4 homogeneous transform, world <- marker
    euler_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)  # (rx, ry, rz) of the rules' table

    @property
    def position(self) -> np.ndarray:
        return self.pose[:3, 3].copy()

    @property
    def rotation(self) -> np.ndarray:
        return self.pose[:3, :3].copy()

    @property
    def normal(self) -> np.ndarray:
        """World direction the printed face looks towards (the marker's +z)."""
        return self.pose[:3, 2].copy()

    @property
    def quaternion_xyzw(self) -> np.ndarray:
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(self.rotation).as_quat()

    @property
    def corners_local(self) -> np.ndarray:
        """4x3 corners in the marker frame, OpenCV order (object points for solvePnP)."""
        return CORNER_UNITS * self.size

    @property
    def corners(self) -> np.ndarray:
        """4x3 world corners in OpenCV order: top-left, top-right, bottom-right, bottom-left."""
        return self.corners_local @ self.rotation.T + self.position


@dataclass(frozen=True)
class Box:
    """A static wall or rib: an axis-aligned (after ``yaw``) box; ``center`` is its centre in 3D."""

    name: str
    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0

    @property
    def half_extents(self) -> np.ndarray:
        return np.asarray(self.size) / 2.0

    @property
    def plan(self) -> tuple[float, float, float, float, float, float]:
        """The box seen from above, as ray casts want it: (cx, cy, half x, half y, cos yaw, sin yaw)."""
        return (self.center[0], self.center[1], self.size[0] / 2, self.size[1] / 2, math.cos(self.yaw),
                math.sin(self.yaw))

    def footprint(self) -> np.ndarray:
        """4x2 world corners of the box's footprint, counter-clockwise."""
        hx, hy = self.size[0] / 2, self.size[1] / 2
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        return local @ np.array([[c, s], [-s, c]]) + np.asarray(self.center[:2])


@dataclass(frozen=True)
class Slot:
    """A place where a part stands. ``facing`` is the world heading of the part's plate (rad)."""

    zone: Zone
    number: int  # server numbering: warehouses 1-4 by increasing x; machines 1 2 / 3 4
    role: SlotRole
    xy: tuple[float, float]
    facing: float

    @property
    def name(self) -> str:
        return f"{self.zone}_{self.number}"


@dataclass(frozen=True)
class PartSpec:
    width: float  # along the plate (the 90 mm face)
    depth: float  # from the plate to the back (60 mm)
    body_height: float
    feet_height: float
    plate: tuple[float, float]  # plate width, height
    tag_size: float
    mass: float

    @property
    def height(self) -> float:
        return self.body_height + self.feet_height


@dataclass(frozen=True)
class Area:
    name: str
    x: tuple[float, float]
    y: tuple[float, float]

    def contains(self, x: float, y: float) -> bool:
        return self.x[0] <= x <= self.x[1] and self.y[0] <= y <= self.y[1]

    @property
    def center(self) -> tuple[float, float]:
        return ((self.x[0] + self.x[1]) / 2, (self.y[0] + self.y[1]) / 2)


@dataclass(frozen=True)
class Pose2D:
    x: float
    y: float
    theta: float


@dataclass(frozen=True)
class Field:
    """The whole competition map. Look markers up with :meth:`marker`, slots with :meth:`slot`."""

    name: str
    description: str
    dictionary: str
    floor: Area
    markers: tuple[Marker, ...]
    boxes: tuple[Box, ...]
    slots: tuple[Slot, ...]
    part: PartSpec
    start_area: Area
    start_pose: Pose2D
    team_areas: tuple[Area, ...]
    beacon_diameter: float
    beacon_height: float
    beacons: tuple[tuple[float, float], ...]
    _by_id: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self):
        self._by_id.update({m.id: m for m in self.markers})

    def boxes_at_height(self, z: float) -> tuple[Box, ...]:
        """The boxes whose vertical extent holds height ``z`` (m): what a scan plane at ``z`` cuts."""
        return tuple(b for b in self.boxes if abs(z - b.center[2]) <= b.size[2] / 2)

    def marker(self, marker_id: int) -> Marker:
        try:
            return self._by_id[marker_id]
        except KeyError:
            raise KeyError(f"marker {marker_id} is not on field {self.name!r}") from None

    def has_marker(self, marker_id: int) -> bool:
        return marker_id in self._by_id

    @property
    def marker_ids(self) -> list[int]:
        return sorted(self._by_id)

    def floor_markers(self) -> list[Marker]:
        return [m for m in self.markers if m.kind == "floor"]

    def wall_markers(self) -> list[Marker]:
        return [m for m in self.markers if m.kind == "wall"]

    def slots_of(self, zone: Zone) -> list[Slot]:
        return sorted((s for s in self.slots if s.zone == zone), key=lambda s: s.number)

    def slot(self, zone: Zone, number: int) -> Slot:
        for s in self.slots:
            if s.zone == zone and s.number == number:
                return s
        raise KeyError(f"no slot {number} in {zone!r}")
