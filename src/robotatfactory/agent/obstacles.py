"""The field's obstacles for the robot: exact polygons (walls, ribs, parts) and a clearance grid.

Everything that can touch the robot's base is an obstacle: the walls and ribs of the warehouses and
machines (``field.boxes``; the lowest, a 65 mm rib, is taller than the base's top at 47.5 mm), the parts
standing on the floor (a box ``depth + plate`` by ``width`` around the part, the plate towards its
facing) and the edge of the floor (the robot must never leave the field). The grid holds, per cell
(``resolution`` m, field frame), the distance in metres from the cell centre to the nearest obstacle
(0 inside one): a robot whose turning circle has radius r fits wherever that clearance exceeds r.

**Decision: the floor's edge.** No perimeter wall is specified; the printed floor is 1.682 x 1.189 m and
the rules allow 1.7 x 1.2 m. The outline may overhang the printed edge by ``floor_overhang`` (default
2 cm, within the rules' area): a robot carrying a part from incoming slot 1 (14.6 cm from the edge) must
turn there with a 15 cm turning circle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .footprint import PLATE_THICKNESS, Footprint

SEARCHES_KEPT = 512  # planner searches remembered per obstacle set (FieldObstacles.searches)


@dataclass(frozen=True)
class PartObstacle:
    """A part standing at (x, y) (its centre, m) with its plate towards ``facing`` (rad)."""

    x: float
    y: float
    facing: float


def _rect_polygon(cx: float, cy: float, sx: float, sy: float, yaw: float) -> np.ndarray:
    hx, hy = sx / 2, sy / 2
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    return local @ np.array([[c, s], [-s, c]]) + (cx, cy)


def square_polygon(x: float, y: float, side: float) -> np.ndarray:
    """4x2 corners of an axis-aligned square of ``side`` m centred at (x, y): a spot to keep away from."""
    return _rect_polygon(x, y, side, side, 0.0)


def part_polygon(part_spec, p: PartObstacle) -> np.ndarray:
    """4x2 corners of a standing part (body plus plate), field frame."""
    d = float(part_spec.depth) + PLATE_THICKNESS
    off = PLATE_THICKNESS / 2  # the plate side is the part's +x
    return _rect_polygon(p.x + off * math.cos(p.facing), p.y + off * math.sin(p.facing), d,
                         float(part_spec.width), p.facing)


def polygons_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Separating-axis test for two convex polygons (Nx2, either winding). Touching counts as overlap."""
    for poly in (a, b):
        n = len(poly)
        for i in range(n):
            e = poly[(i + 1) % n] - poly[i]
            axis = np.array([-e[1], e[0]])
            pa, pb = a @ axis, b @ axis
            if pa.max() < pb.min() or pb.max() < pa.min():
                return False
    return True


class FieldObstacles:
    """Obstacles of one field plus the parts given; exact checks and the clearance grid."""

    def __init__(self, field, parts: tuple[PartObstacle, ...] | list[PartObstacle] = (), resolution: float = 0.01,
                 floor_overhang: float = 0.02, extra=()):
        self.field = field
        self.parts = tuple(parts)
        self.resolution = res = float(resolution)
        self.polygons: list[np.ndarray] = [b.footprint() for b in field.boxes]
        self.polygons += [part_polygon(field.part, p) for p in self.parts]
        self.polygons += [np.asarray(e, dtype=float).reshape(-1, 2) for e in extra]  # convex, e.g. a blocked spot
        # the quadrilaterals (every wall, rib, part and blocked spot) stacked for the exact test, the rest apart
        self._quad_index = [k for k, poly in enumerate(self.polygons) if poly.shape == (4, 2)]
        self._quads = np.array([self.polygons[k] for k in self._quad_index], dtype=float).reshape(-1, 4, 2)
        self._quad_axes = _edge_normals(self._quads)
        self._centres = np.array([poly.mean(axis=0) for poly in self.polygons])
        self._radii = np.array([np.max(np.hypot(*(poly - poly.mean(axis=0)).T)) for poly in self.polygons])
        o = float(floor_overhang)
        fx = (field.floor.x[0] - o, field.floor.x[1] + o)
        fy = (field.floor.y[0] - o, field.floor.y[1] + o)
        self.floor = (fx, fy)  # the area the outline must stay in (m)
        # one ring of cells outside the floor, all occupied
        self.x0, self.y0 = fx[0] - res, fy[0] - res
        self.nx = int(math.ceil((fx[1] - fx[0]) / res)) + 2
        self.ny = int(math.ceil((fy[1] - fy[0]) / res)) + 2
        half_diag = res / math.sqrt(2)
        xs = self.x0 + (np.arange(self.nx) + 0.5) * res
        ys = self.y0 + (np.arange(self.ny) + 0.5) * res
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        occ = (X < fx[0]) | (X > fx[1]) | (Y < fy[0]) | (Y > fy[1])
        for poly in self.polygons:
            occ |= _inside_convex(poly, X, Y, pad=half_diag)
        self.occupied = occ
        # every cell an obstacle reaches into is occupied (its centre is within half a diagonal of the
        # obstacle); so the distance to the nearest occupied centre, less half a diagonal, is a lower bound
        # of the distance to the nearest obstacle
        d = ndimage.distance_transform_edt(~occ) * res - half_diag
        self.clearance = np.where(occ, 0.0, np.maximum(d, 0.0))
        #: the planner's grid searches on these obstacles, by query (planner.PathPlanner._astar): the obstacles
        #: never change once made, so neither does a search's result. Written through :meth:`remember`
        self.searches: dict = {}

    # ------------------------------------------------------------------------------------------ grid
    def cell(self, x: float, y: float) -> tuple[int, int]:
        """The cell (i, j) holding (x, y), clipped to the grid."""
        i = int((x - self.x0) / self.resolution)
        j = int((y - self.y0) / self.resolution)
        return min(max(i, 0), self.nx - 1), min(max(j, 0), self.ny - 1)

    def center(self, i: int, j: int) -> tuple[float, float]:
        r = self.resolution
        return self.x0 + (i + 0.5) * r, self.y0 + (j + 0.5) * r

    def clearance_at(self, x: float, y: float) -> float:
        """Clearance (m) of the cell holding (x, y), less the point's offset from the cell centre."""
        i, j = self.cell(x, y)
        cx, cy = self.center(i, j)
        return max(0.0, float(self.clearance[i, j]) - math.hypot(x - cx, y - cy))

    def clearance_of(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """:meth:`clearance_at` of many points at once (arrays of x and y, m)."""
        r = self.resolution
        i = np.minimum(np.maximum(((x - self.x0) / r).astype(int), 0), self.nx - 1)  # (astype: towards 0, as int())
        j = np.minimum(np.maximum(((y - self.y0) / r).astype(int), 0), self.ny - 1)
        off = np.hypot(x - (self.x0 + (i + 0.5) * r), y - (self.y0 + (j + 0.5) * r))
        return np.maximum(0.0, self.clearance[i, j] - off)

    def segment_clear(self, a, b, radius: float) -> bool:
        """True when every point of the segment a-b (m) has clearance >= ``radius``."""
        n = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / (self.resolution / 2)) + 1)
        u = np.arange(n) / (n - 1)
        return not (self.clearance_of(a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])) < radius).any()

    def segments_clearance(self, a, ends: np.ndarray) -> np.ndarray:
        """The least clearance (m) along each segment from ``a`` to each of ``ends`` (n, 2), sampled as
        :meth:`segment_clear` samples (at least every half cell): ``>= radius`` where it would say clear."""
        ends = np.asarray(ends, dtype=float).reshape(-1, 2)
        longest = float(np.max(np.hypot(ends[:, 0] - a[0], ends[:, 1] - a[1]), initial=0.0))
        u = np.arange(n := max(2, int(longest / (self.resolution / 2)) + 1)) / (n - 1)
        x = a[0] + u[None] * (ends[:, 0:1] - a[0])
        y = a[1] + u[None] * (ends[:, 1:2] - a[1])
        return self.clearance_of(x, y).min(axis=1)

    # ------------------------------------------------------------------------------------------ exact
    def collides_any(self, footprint: Footprint, x: np.ndarray, y: np.ndarray, theta: float) -> bool:
        """:meth:`collides` for many positions at one heading (arrays of x and y, m): does any of them?"""
        return self.collides_poses(footprint, x, y, np.full(len(x), float(theta)))

    def collides_poses(self, footprint: Footprint, x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> bool:
        """:meth:`collides` for many poses at once (arrays of x, y and heading): does any of them?"""
        if len(x) == 0:
            return False
        corners = footprint.corners_at_poses(x, y, theta)  # (poses, rects, 4, 2)
        d = np.hypot(self._centres[:, 0][None] - x[:, None], self._centres[:, 1][None] - y[:, None])
        near = (d <= (self._radii + footprint.radius)[None]).any(axis=0)
        return self._corners_collide(corners.reshape(-1, 4, 2), near, check_floor=True)

    def sweep_collides(self, footprint: Footprint, a, b) -> bool:
        """Does the outline, moving straight from ``a`` to ``b`` (x, y) heading along the line, overlap an obstacle
        or leave the floor? Exact, not sampled: per rectangle the convex hull of where it starts and ends (the area
        a translated convex shape sweeps), a few polygons whatever the length."""
        h = math.atan2(b[1] - a[1], b[0] - a[0])
        ends = np.concatenate([footprint.corners_at(a[0], a[1], h), footprint.corners_at(b[0], b[1], h)], axis=1)
        hulls = np.array([_hull8(c) for c in ends])  # (rects, 8, 2)
        near = _segment_distance(self._centres, a, b) <= self._radii + footprint.radius
        return self._corners_collide(hulls, near, check_floor=True)

    def collides(self, footprint: Footprint, pose: tuple[float, float, float], ignore_floor: bool = False) -> bool:
        """Exact test: does the outline at ``pose`` overlap an obstacle or leave the floor?"""
        near = np.hypot(self._centres[:, 0] - pose[0], self._centres[:, 1] - pose[1]) <= self._radii + footprint.radius
        return self._corners_collide(footprint.corners_at(*pose), near, check_floor=not ignore_floor)

    def _corners_collide(self, corners: np.ndarray, near: np.ndarray, check_floor: bool) -> bool:
        """Do the rectangles ``corners`` (n, 4, 2) leave the floor (``check_floor``) or overlap an obstacle
        flagged in ``near`` (a boolean per polygon: the only ones tested)?"""
        (fx0, fx1), (fy0, fy1) = self.floor
        if check_floor and (corners[..., 0].min() < fx0 or corners[..., 0].max() > fx1
                            or corners[..., 1].min() < fy0 or corners[..., 1].max() > fy1):
            return True
        quads = near[self._quad_index]
        if quads.any() and _quads_overlap(corners, self._quads[quads], self._quad_axes[quads]).any():
            return True
        others = [self.polygons[k] for k in np.flatnonzero(near) if self.polygons[k].shape != (4, 2)]
        return any(polygons_overlap(poly, ob) for poly in corners for ob in others)

    # ------------------------------------------------------------------------------------------ memo
    def remember(self, key, value):
        """Keep ``value`` under ``key`` in :attr:`searches` (at most :data:`SEARCHES_KEPT` entries: past that the
        memo starts again) and return it."""
        if len(self.searches) >= SEARCHES_KEPT:
            self.searches.clear()
        self.searches[key] = value
        return value


def _hull8(pts: np.ndarray) -> np.ndarray:
    """The convex hull of 8 points (8, 2) as 8 corners in order (the last repeated where it has fewer)."""
    p = sorted(map(tuple, pts.tolist()))

    def half(seq):
        out = []
        for q in seq:
            while len(out) >= 2 and ((out[-1][0] - out[-2][0]) * (q[1] - out[-2][1])
                                     - (out[-1][1] - out[-2][1]) * (q[0] - out[-2][0])) <= 0:
                out.pop()
            out.append(q)
        return out[:-1]

    hull = half(p) + half(reversed(p))
    return np.array(hull + [hull[-1]] * (8 - len(hull)))


def _segment_distance(points: np.ndarray, a, b) -> np.ndarray:
    """Distance (m) of each of ``points`` (n, 2) from the segment a-b."""
    ab = np.array([b[0] - a[0], b[1] - a[1]])
    ap = points - np.asarray(a[:2], dtype=float)
    u = np.clip(ap @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.hypot(*(ap - u[:, None] * ab).T)


def _edge_normals(quads: np.ndarray) -> np.ndarray:
    """Each edge's normal (not unit length) of each quadrilateral (n, 4, 2): the separating axes."""
    e = np.roll(quads, -1, axis=1) - quads
    return np.stack((-e[..., 1], e[..., 0]), axis=-1)


def _quads_overlap(a: np.ndarray, b: np.ndarray, b_axes: np.ndarray) -> np.ndarray:
    """:func:`polygons_overlap` for convex polygons, every one of ``a`` (n, k, 2: k corners in order, any k)
    against every quadrilateral of ``b`` (m, 4, 2, edge normals ``b_axes``): (n, m) booleans. Touching counts
    as overlap."""
    a_axes = _edge_normals(a)
    # projections on a's axes: a's corners (n, 4 axes, 4 corners), b's (n, m, 4, 4)
    pa = np.einsum("nad,ncd->nac", a_axes, a)
    pb = np.einsum("nad,mcd->nmac", a_axes, b)
    sep = ((pa.max(-1)[:, None] < pb.min(-1)) | (pb.max(-1) < pa.min(-1)[:, None])).any(-1)
    # and on b's axes: b's corners (m, 4, 4), a's (n, m, 4, 4)
    qb = np.einsum("mad,mcd->mac", b_axes, b)
    qa = np.einsum("mad,ncd->nmac", b_axes, a)
    sep |= ((qa.max(-1) < qb.min(-1)[None]) | (qb.max(-1)[None] < qa.min(-1))).any(-1)
    return ~sep


def _inside_convex(poly: np.ndarray, X: np.ndarray, Y: np.ndarray, pad: float = 0.0) -> np.ndarray:
    """Points (X, Y) inside the convex polygon grown by ``pad`` m (any winding)."""
    n = len(poly)
    area = sum(poly[i, 0] * poly[(i + 1) % n, 1] - poly[(i + 1) % n, 0] * poly[i, 1] for i in range(n))
    sign = 1.0 if area > 0 else -1.0
    inside = np.ones_like(X, dtype=bool)
    for i in range(n):
        p, q = poly[i], poly[(i + 1) % n]
        e = q - p
        L = math.hypot(e[0], e[1])
        # signed distance to the left of the edge (inside for a counter-clockwise polygon)
        dist = sign * (e[0] * (Y - p[1]) - e[1] * (X - p[0])) / L
        inside &= dist >= -pad
    return inside
