"""Finding a part that fell off the magnet: where it most likely lies, and where the LIDAR sees it.

Plain Python, no ROS. A carried part that is lost on the way (the contact switch released while carrying) lies
somewhere near where it fell. :func:`lost_spot` says where it was when the switch last saw it: the held part's
centre in front of the magnet (base_link + magnet face + hold gap + plate + depth / 2 along the heading), its
plate towards the robot. :func:`find_part` looks for it in one LIDAR sweep (:class:`Scan`): the returns near
that spot that the map does not explain (walls, ribs, machines, the parts the server's state lists: what
:class:`~.obstacles.FieldObstacles` holds) are the part, and its centre and axes are fitted to them.

The LIDAR and a lying part (robot file ``lidar.xyz`` z = 0.05 m; the field's part: feet 5 mm, body 60 mm, so
its body spans z = 0.005-0.065 m): the scan plane cuts the part's body, so a part lying upright on the floor
gives returns on the one or two faces that look at the sensor (the stand-in: part bodies are in the LIDAR's geom
groups, sim/scene.py). The ferromagnetic plate (z = 0.025-0.045 m, 2 mm proud) is below the scan plane: the
LIDAR sees a 60 x 90 mm box and cannot tell which of its two long faces carries the plate.
:class:`FoundPart` therefore gives both; the one that faced the robot when the part fell comes first (a part
sliding off the magnet's face turns, but rarely by more than a quarter turn), the pick tries the other one next.

The fit (:func:`fit_box`): the orientation whose bounding box the points hug best (the sum of each point's
distance to the nearest side of the box, over 0-90 degrees in 1 degree steps: the "closeness" criterion of
L-shape fitting), then which axis is the long one (the one the points' extent allows; both: the hint's), then
the centre from the visible faces: a face the sensor looks at is the box's side nearest the sensor (where its
points lie: their median), the centre half the part's size behind it; along a face seen whole, its middle.

Units: metres, radians, seconds; the field frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .footprint import HOLD_GAP, PLATE_THICKNESS, Footprint, wrap
from .obstacles import FieldObstacles


#: m around the robot's outline within which a return is the robot's own (SimTwo's rays hit its wheels, at
#: 0.065-0.07 m with 1.6 mm of noise; the bridge's self filter takes 9 mm)
OWN_MARGIN = 0.009


@dataclass(frozen=True)
class Scan:
    """One LIDAR sweep as the agent takes it (a ``sensor_msgs/LaserScan`` without ROS): ray ``i`` looks at
    ``angle_min + i * angle_increment`` (rad, laser frame) and was measured at ``t0 + i * time_increment`` (s);
    ``ranges`` (m): a non-finite value, a negative one (SimTwo's -1) or one outside [range_min, range_max] is no
    return."""

    t0: float
    ranges: tuple
    angle_min: float
    angle_increment: float
    time_increment: float = 0.0
    range_min: float = 0.0
    range_max: float = math.inf

    @classmethod
    def from_lidar(cls, lidar, t0: float, ranges, time_increment: float = 0.0) -> Scan:
        """A sweep of the robot file's LIDAR (:class:`~robotatfactory.robot.LidarSpec`: SimTwo's ranger2d, N rays
        from -fov/2 in steps of fov/(N-1))."""
        n = len(ranges)
        fov = math.radians(float(lidar.fov_deg))
        return cls(float(t0), tuple(float(r) for r in ranges), -fov / 2, fov / (n - 1) if n > 1 else 0.0,
                   float(time_increment), float(lidar.range_min), float(lidar.range_max))

    @property
    def t_end(self) -> float:
        """When its last ray was measured (s)."""
        return self.t0 + max(len(self.ranges) - 1, 0) * self.time_increment

    def points(self, pose, mount=(0.0, 0.0)) -> np.ndarray:
        """The returns as field-frame points (n x 2) with base_link at ``pose`` (x, y, theta) for the whole sweep
        (a robot standing still) and the laser at ``mount`` (x, y) in base_link."""
        r = np.asarray(self.ranges, dtype=float)
        a = self.angle_min + np.arange(len(r)) * self.angle_increment
        ok = np.isfinite(r) & (r >= max(self.range_min, 0.0)) & (r <= self.range_max) & (r > 0.0)
        r, a = r[ok], a[ok]
        x, y, th = (float(v) for v in pose[:3])
        c, s = math.cos(th), math.sin(th)
        lx, ly = x + c * mount[0] - s * mount[1], y + s * mount[0] + c * mount[1]
        return np.column_stack([lx + r * np.cos(th + a), ly + r * np.sin(th + a)])


@dataclass(frozen=True)
class FoundPart:
    """A part on the floor: its centre (m) and the headings its plate may face (rad, the likelier first);
    ``points``: the LIDAR returns it was fitted to (0: not seen, the spot where it was lost)."""

    x: float
    y: float
    facings: tuple[float, ...]
    points: int = 0

    @property
    def xy(self) -> tuple[float, float]:
        return (self.x, self.y)


@dataclass(frozen=True)
class FloorSlot:
    """A part lying on the floor as the planner and the docker take a slot: its centre ``xy`` (m) and the
    heading the pick comes from (``facing``, rad: the robot faces the other way); ``plate``: the heading its plate
    faces (None: ``facing``; an approach at an angle to the plate's normal differs)."""

    xy: tuple[float, float]
    facing: float
    plate: float | None = None
    name: str = "the part on the floor"
    role: str = "floor"

    def __post_init__(self):
        if self.plate is None:
            object.__setattr__(self, "plate", self.facing)


def lost_spot(pose, magnet_x: float, part) -> FoundPart:
    """Where a part held on the magnet lies if it dropped straight down at ``pose`` (base_link, x, y, theta): its
    centre in front of the magnet, its plate facing the robot."""
    d = float(magnet_x) + HOLD_GAP + PLATE_THICKNESS + float(part.depth) / 2
    x, y, th = (float(v) for v in pose[:3])
    return FoundPart(x + d * math.cos(th), y + d * math.sin(th), (wrap(th + math.pi),))


def distances_to(polygons, pts: np.ndarray) -> np.ndarray:
    """Each point's distance (m) to the nearest of ``polygons`` (convex, k x 2; 0 inside one)."""
    out = np.full(len(pts), np.inf)
    if not len(pts):
        return out
    for poly in polygons:
        poly = np.asarray(poly, dtype=float)
        n = len(poly)
        a = poly
        b = np.roll(poly, -1, axis=0)
        # distance to each edge segment
        e = b - a  # n x 2
        ee = np.maximum((e ** 2).sum(axis=1), 1e-18)
        w = pts[:, None, :] - a[None, :, :]  # m x n x 2
        u = np.clip((w * e[None]).sum(axis=2) / ee[None], 0.0, 1.0)
        d = np.hypot(*(w - u[..., None] * e[None]).transpose(2, 0, 1)).min(axis=1)
        # inside (convex, either winding): the same side of every edge
        cross = e[None, :, 0] * w[..., 1] - e[None, :, 1] * w[..., 0]
        inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
        d = np.where(inside, 0.0, d) if n >= 3 else d
        out = np.minimum(out, d)
    return out


def unexplained(pts: np.ndarray, obstacles: FieldObstacles, margin: float) -> np.ndarray:
    """The mask of points farther than ``margin`` m from every wall, rib and listed part of ``obstacles`` and
    on the floor (its edge grown by ``margin``): what the map does not explain."""
    if not len(pts):
        return np.zeros(0, dtype=bool)
    (fx0, fx1), (fy0, fy1) = obstacles.floor
    on_floor = (pts[:, 0] >= fx0 - margin) & (pts[:, 0] <= fx1 + margin) & (pts[:, 1] >= fy0 - margin) & \
               (pts[:, 1] <= fy1 + margin)
    return on_floor & (distances_to(obstacles.polygons, pts) > margin)


def clusters(pts: np.ndarray, gap: float) -> list[np.ndarray]:
    """Single-link clusters of ``pts`` (neighbours within ``gap`` m), as index arrays."""
    n = len(pts)
    if not n:
        return []
    d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    near = d <= gap
    label = -np.ones(n, dtype=int)
    out = []
    for i in range(n):
        if label[i] >= 0:
            continue
        stack, members = [i], []
        label[i] = len(out)
        while stack:
            k = stack.pop()
            members.append(k)
            for j in np.flatnonzero(near[k] & (label < 0)):
                label[j] = len(out)
                stack.append(j)
        out.append(np.array(sorted(members)))
    return out


def fit_box(pts: np.ndarray, sensor_xy, depth: float, width: float, facing_hint: float,
            tol: float = 0.012) -> tuple[float, float, float] | None:
    """The centre (x, y) and the depth axis (rad, in [0, pi): the plate is on one of its two ends) of a
    ``depth`` x ``width`` box whose sides facing ``sensor_xy`` gave the points ``pts`` (n x 2); None when no
    box of that size fits them within ``tol`` m. ``facing_hint``: the likelier direction of the depth axis
    (decides when the points allow either axis, a single face seen)."""
    if len(pts) < 2:
        return None
    best = None
    for deg in range(90):
        phi = math.radians(deg)
        c, s = math.cos(phi), math.sin(phi)
        u = pts @ np.array([c, s])
        v = pts @ np.array([-s, c])
        cost = np.minimum.reduce([u - u.min(), u.max() - u, v - v.min(), v.max() - v]).sum()
        if best is None or cost < best[0] - 1e-12:
            best = (cost, phi)
    phi = best[1]
    c, s = math.cos(phi), math.sin(phi)
    U, V = np.array([c, s]), np.array([-s, c])
    u, v = pts @ U, pts @ V
    eu, ev = u.max() - u.min(), v.max() - v.min()
    su, sv = float(np.dot(sensor_xy, U)), float(np.dot(sensor_xy, V))
    options = []  # (size along u, size along v, depth axis angle)
    if eu <= width + tol and ev <= depth + tol:
        options.append((width, depth, phi + math.pi / 2))
    if eu <= depth + tol and ev <= width + tol:
        options.append((depth, width, phi))
    if not options:
        return None

    def axis_gap(a: float) -> float:  # the depth axis (either way) against the hint
        return abs(wrap(2 * (a - facing_hint))) / 2

    options.sort(key=lambda o: axis_gap(o[2]))
    du, dv, axis = options[0]

    def face(c: np.ndarray, other: np.ndarray, near_lo: bool) -> float | None:
        """Where the face across this axis on the sensor's side lies (the median of its points, taken twice so
        that the noisy extreme does not bias it), or None when too few points spread along it."""
        edge = c.min() if near_lo else c.max()
        on = np.abs(c - edge) <= 2 * tol / 3
        for _ in range(2):
            if on.sum() < 3 or np.ptp(other[on]) < 0.015:
                return None
            edge = float(np.median(c[on]))
            on = np.abs(c - edge) <= tol / 2
        return edge

    def centre(c: np.ndarray, other: np.ndarray, size: float, sensor: float) -> float:
        lo, hi = float(c.min()), float(c.max())
        near_lo = sensor < (lo + hi) / 2
        f = face(c, other, near_lo)
        if f is not None:  # a face across this axis seen: the centre half the size behind it
            return f + size / 2 if near_lo else f - size / 2
        if hi - lo >= size - tol:  # only the faces along this axis: the middle of their extent
            return (lo + hi) / 2
        return lo + size / 2 if near_lo else hi - size / 2

    cu = centre(u, v, du, su)
    cv = centre(v, u, dv, sv)
    xy = cu * U + cv * V
    return float(xy[0]), float(xy[1]), float(axis % math.pi)


def find_part(scan: Scan, pose, mount, near: FoundPart, obstacles: FieldObstacles, part, own: Footprint,
              radius: float, margin: float, min_points: int = 3, gap: float = 0.03) -> FoundPart | None:
    """The part nearest ``near`` (where it was lost) in ``scan`` taken with base_link at ``pose`` (standing) and
    the laser at ``mount`` (x, y in base_link), or None. Returns farther than ``radius`` m from ``near``, within
    ``margin`` of the map (``obstacles``: walls, ribs, listed parts, the floor) or inside the robot's own
    outline ``own`` grown by :data:`OWN_MARGIN` (its wheels; but ahead of the magnet's face, where a part touching it
    lies) are ignored; the rest are clustered (``gap``) and the nearest cluster of at
    least ``min_points`` that a part-sized box fits (:func:`fit_box`) is the part. Its ``facings``: the plate's
    two possible headings, the one nearer ``near.facings[0]`` first."""
    pts = scan.points(pose, mount)
    if not len(pts):
        return None
    keep = np.hypot(pts[:, 0] - near.x, pts[:, 1] - near.y) <= radius
    pts = pts[keep]
    if len(pts):  # the robot's own wheels (rays hit them; never anything ahead of the magnet's face)
        mine = np.zeros(len(pts), dtype=bool)
        for poly in own.inflated(OWN_MARGIN).polygons(*pose[:3]):
            mine |= distances_to([poly], pts) == 0.0
        ahead = (pts[:, 0] - pose[0]) * math.cos(pose[2]) + (pts[:, 1] - pose[1]) * math.sin(pose[2]) > own.front
        pts = pts[~mine | ahead]
    pts = pts[unexplained(pts, obstacles, margin)] if len(pts) else pts
    if len(pts) < min_points:
        return None
    x, y, th = (float(v) for v in pose[:3])
    sensor = (x + math.cos(th) * mount[0] - math.sin(th) * mount[1], y + math.sin(th) * mount[0] + math.cos(th) * mount[1])
    hint = near.facings[0]
    found = []
    for idx in clusters(pts, gap):
        if len(idx) < min_points:
            continue
        fit = fit_box(pts[idx], sensor, float(part.depth), float(part.width), hint)
        if fit is None:
            continue
        cx, cy, axis = fit
        a1 = axis if abs(wrap(axis - hint)) <= math.pi / 2 else wrap(axis + math.pi)
        found.append((math.hypot(cx - near.x, cy - near.y), FoundPart(cx, cy, (wrap(a1), wrap(a1 + math.pi)), len(idx))))
    if not found:
        return None
    return min(found, key=lambda f: f[0])[1]
