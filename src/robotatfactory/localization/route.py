"""The localization experiment's routes and a pure-pursuit controller to drive them.

Two routes, both closed laps starting at the field's start pose (-0.725, -0.4) heading +y, both keeping at
least 0.12 m between the robot's centre and any wall or rib and 0.15 m from any part slot:

- ``reference`` (:data:`LOOP`): the loop the localization was developed and tuned on. It visits the whole
  field clockwise -- the west side past the start area, along the incoming warehouse, the north-east, down
  the east side, along the outgoing warehouse, up the corridor between the machines and round machine A --
  at one cruise speed.
- ``second`` (:data:`EIGHT`): held out (nothing was tuned on it). A figure-eight round the two machines --
  machine A clockwise, machine B anticlockwise, crossing diagonally between them -- with five visits that
  end facing a station close up (incoming warehouse slot 2, outgoing warehouse slot 3, machine B's input 1,
  machine A's input 3 and the start area), each a sharp turn or a turn on the spot. Its segments have their
  own speeds: 1.25x the cruise speed on the long legs, 0.6x into and out of the visits, so it drives at
  0.12-0.25 m/s with the default 0.2 m/s cruise, and it sees the markers from headings the reference loop
  never has (the east half anticlockwise, the diagonals, the stations head-on).

The controller follows a route with a fixed lookahead; it is fed the ground-truth pose (the experiment
measures localization, so control must not depend on it). No ROS here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .geometry import wrap_angle

#: (x, y) waypoints of one lap of the reference route, starting at the field's start pose (-0.725, -0.4)
#: heading +y; the lap ends with a small loop back into the start area.
LOOP = (
    (-0.725, -0.40), (-0.70, -0.10), (-0.68, 0.30), (-0.45, 0.36), (-0.10, 0.36), (0.15, 0.37),
    (0.55, 0.38), (0.70, 0.25), (0.69, -0.05), (0.66, -0.30), (0.45, -0.36), (0.10, -0.36),
    (0.00, -0.20), (0.00, 0.05), (-0.05, 0.22), (-0.35, 0.245), (-0.61, 0.17), (-0.62, -0.15),
    (-0.58, -0.36), (-0.66, -0.45), (-0.74, -0.36),
)

FAST, SLOW = 1.25, 0.6  # speed factors of the second route's long legs and of its visits
STOP = 1  # a visit: the robot must reach the waypoint (within 2 cm) before it goes on

#: (x, y, speed factor[, STOP]) waypoints of one lap of the second route (the factor applies to the segment
#: that ends at the waypoint; times the cruise speed; STOP marks a visit). Same start as LOOP.
EIGHT = (
    (-0.725, -0.40, 1.0),
    # up the west side, then visit incoming warehouse slot 2 (-0.545, 0.535): in facing it, turn on the spot
    (-0.70, -0.10, FAST), (-0.66, 0.16, FAST), (-0.56, 0.23, SLOW), (-0.545, 0.37, SLOW, STOP), (-0.50, 0.26, SLOW),
    # along the north of machine A heading east, then diagonally between the machines to the south-east
    (-0.36, 0.245, 1.0), (-0.18, 0.22, FAST), (0.00, 0.00, FAST), (0.16, -0.24, FAST), (0.36, -0.29, 1.0),
    # visit outgoing warehouse slot 3 (0.545, -0.535): in facing it, turn on the spot
    (0.50, -0.25, SLOW), (0.545, -0.37, SLOW, STOP), (0.59, -0.25, SLOW),
    # machine B anticlockwise: up the east side, west along its north side
    (0.67, -0.05, FAST), (0.66, 0.30, FAST), (0.55, 0.41, 1.0), (0.25, 0.40, FAST),
    # visit machine B's input 1 (0.3075, 0.15) from the west: in heading east, turn on the spot
    (0.06, 0.30, SLOW), (0.02, 0.17, SLOW), (0.145, 0.15, SLOW, STOP), (0.03, 0.12, SLOW),
    # diagonally back across the middle to the south of machine A, westwards
    (-0.05, -0.12, 1.0), (-0.18, -0.36, 1.0), (-0.40, -0.40, FAST),
    # visit machine A's input 3 (-0.3875, -0.15) from the west: in heading east, turn on the spot
    (-0.60, -0.33, SLOW), (-0.68, -0.17, SLOW), (-0.545, -0.15, SLOW, STOP), (-0.67, -0.19, SLOW),
    # back into the start area with a small loop, ending heading north like the start
    (-0.64, -0.32, 1.0), (-0.60, -0.44, SLOW), (-0.70, -0.48, SLOW), (-0.755, -0.38, SLOW),
)

#: (x, y, speed factor[, STOP]) waypoints of the calibration drive (``raf experiment localization
#: --calibration auto`` records it for ``raf calibrate``): up the west side, along the incoming warehouse,
#: turns on the spot facing the warehouse, the middle and machine A, so that wall and floor markers cross the
#: whole image at many distances. Neither localization route.
CALIBRATION = (
    (-0.725, -0.40, 1.0), (-0.70, -0.05, 1.0), (-0.62, 0.25, 1.0), (-0.40, 0.32, 1.0),
    (-0.40, 0.37, SLOW, STOP), (-0.25, 0.25, 1.0), (-0.05, 0.30, 1.0), (0.00, 0.36, SLOW, STOP),
    (0.00, 0.10, 1.0), (0.02, -0.10, 1.0), (-0.12, -0.10, SLOW, STOP), (0.00, -0.30, 1.0),
    (-0.20, -0.40, 1.0), (-0.50, -0.36, 1.0),
)

ROUTES = ("reference", "second", "calibration")


@dataclass(frozen=True)
class Route:
    """A route to drive: waypoints (N x 2, map frame, m), the speed factor of the segment into each
    waypoint (N; the first is unused; times the cruise speed) and the visits (N booleans: waypoints the robot
    must reach before it goes on, e.g. to face a station and turn on the spot)."""

    name: str
    points: np.ndarray
    speeds: np.ndarray = field(default=None)
    stops: np.ndarray = field(default=None)

    @property
    def start(self) -> tuple[float, float, float]:
        """Start pose (x, y, heading): the first waypoint, heading +y (the field's start heading)."""
        return (float(self.points[0, 0]), float(self.points[0, 1]), math.pi / 2)


def route(laps: int = 2, name: str = "reference") -> np.ndarray:
    """Waypoints of ``laps`` laps of the named route (N x 2)."""
    return make_route(name, laps).points


def make_route(name: str, laps: int = 2) -> Route:
    """``laps`` laps of the route ``name`` (``reference``, ``second`` or ``calibration``), with its speed
    factors and visits."""
    if name == "reference":
        lap = [(x, y, 1.0, 0) for x, y in LOOP]
    elif name in ("second", "calibration"):
        lap = [tuple(w) + (0,) * (4 - len(w)) for w in (EIGHT if name == "second" else CALIBRATION)]
    else:
        raise ValueError(f"unknown route {name!r}: choose one of {', '.join(ROUTES)}")
    if laps < 1:
        raise ValueError("laps must be >= 1")
    pts = [lap[0]]
    for _ in range(laps):
        pts.extend(lap[1:])
    a = np.array(pts, dtype=float)
    return Route(name, a[:, :2].copy(), a[:, 2].copy(), a[:, 3] > 0)


def densify(pts: np.ndarray, step: float = 0.01, values: np.ndarray | None = None):
    """The polyline resampled every ``step`` metres; with ``values`` (one per waypoint, applying to the
    segment into it), also those values per dense point: ``(dense_pts, dense_values)``."""
    out = [pts[0]]
    vals = [values[0]] if values is not None else None
    for k, (a, b) in enumerate(zip(pts[:-1], pts[1:])):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        for i in range(1, n + 1):
            out.append(a + (b - a) * i / n)
            if vals is not None:
                vals.append(values[k + 1])
    if values is None:
        return np.array(out)
    return np.array(out), np.array(vals, dtype=float)


def length(pts: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


@dataclass
class PurePursuit:
    """Follows a polyline: steers towards the point ``lookahead`` ahead along the path from the closest point,
    slows down in turns, stops at the end. ``command(pose)`` -> (v, w) in m/s and rad/s. ``speeds`` (one
    factor per waypoint, for the segment into it) scales ``speed`` along the path; the controller slows
    for a slower segment from the lookahead on."""

    path: np.ndarray  # waypoints (N x 2), resampled every centimetre
    speed: float = 0.2
    lookahead: float = 0.10
    max_w: float = 3.0
    goal_tolerance: float = 0.02
    speeds: np.ndarray | None = None  # per-waypoint speed factors (N), None: 1 everywhere
    stops: np.ndarray | None = None  # per-waypoint visits (N booleans): reach them before going on
    stop_tolerance: float = 0.02
    _i: int = 0  # progress index: never goes back (so crossing paths are followed in order)

    def __post_init__(self):
        pts = np.asarray(self.path, dtype=float)
        f = np.ones(len(pts)) if self.speeds is None else np.asarray(self.speeds, dtype=float).reshape(-1)
        if len(f) != len(pts):
            raise ValueError("speeds: one factor per waypoint")
        self.path, self._f = densify(pts, values=f)
        self._stops: list[int] = []  # dense indices of the visits not reached yet
        if self.stops is not None:
            st = np.asarray(self.stops, dtype=bool).reshape(-1)
            if len(st) != len(pts):
                raise ValueError("stops: one flag per waypoint")
            _, idx = densify(pts, values=np.arange(len(pts), dtype=float))
            self._stops = [int(np.flatnonzero(idx == k)[-1]) for k in np.flatnonzero(st) if k > 0]
        self._s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(self.path, axis=0), axis=1))])

    @classmethod
    def for_route(cls, r: Route, speed: float = 0.2, **kw) -> "PurePursuit":
        return cls(r.points, speed=speed, speeds=r.speeds, stops=r.stops, **kw)

    @property
    def progress(self) -> float:
        """Fraction of the path done (0..1)."""
        return float(self._s[self._i] / self._s[-1]) if self._s[-1] > 0 else 1.0

    _at_goal: bool = False

    @property
    def done(self) -> bool:
        return self._at_goal

    def command(self, pose: tuple[float, float, float]) -> tuple[float, float]:
        x, y, th = pose
        p = np.array([x, y])
        # advance the progress index along a window ahead (no jumping to a later crossing)
        while self._stops and np.linalg.norm(self.path[self._stops[0]] - p) < self.stop_tolerance:
            self._stops.pop(0)  # visit reached
        hi = min(len(self.path), self._i + 60, self._stops[0] + 1 if self._stops else len(self.path))
        d = np.linalg.norm(self.path[self._i:hi] - p, axis=1)
        self._i += int(np.argmin(d))
        goal = self.path[-1]
        if self._i >= len(self.path) - 2 and np.linalg.norm(goal - p) < self.goal_tolerance:
            self._at_goal = True
            return 0.0, 0.0
        target_s = self._s[self._i] + self.lookahead
        j = min(int(np.searchsorted(self._s, target_s)), len(self.path) - 1)
        if self._stops:  # steer at a visit, not past it
            j = min(j, self._stops[0])
        tgt = self.path[j]
        dx, dy = tgt - p
        c, s = math.cos(th), math.sin(th)
        lx, ly = c * dx + s * dy, -s * dx + c * dy  # target in the robot frame
        L2 = lx * lx + ly * ly
        if L2 < 1e-12:
            return 0.0, 0.0
        alpha = math.atan2(ly, lx)
        if abs(alpha) > math.radians(60):  # far off the heading: turn on the spot first
            return 0.0, math.copysign(min(self.max_w, 2.5 * abs(alpha)), alpha)
        curvature = 2 * ly / L2
        factor = float(np.min(self._f[self._i:j + 1]))
        v = self.speed * factor / (1 + 0.15 * abs(curvature))
        remaining = self._s[-1] - self._s[self._i]
        if self._stops:
            remaining = min(remaining, float(np.linalg.norm(self.path[self._stops[0]] - p)))
        v = min(v, max(0.03, 1.5 * remaining))
        w = max(-self.max_w, min(self.max_w, v * curvature))
        return v, w


def heading_error(a: float, b: float) -> float:
    return abs(wrap_angle(a - b))
