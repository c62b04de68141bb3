"""Paths on the field for the robot's footprint: grid A* on the clearance map, then shortcut smoothing;
approach poses in front of every slot.

A path is a polyline of (x, y) waypoints in the field frame (m). Every point of it keeps the robot's
turning circle (:attr:`Footprint.radius` plus ``margin``) clear of walls, ribs, parts and the floor's edge,
so the robot may turn in place at any waypoint and drive straight between them. A* runs on the 8-connected
grid of :class:`~.obstacles.FieldObstacles`, its step cost raised near obstacles (``keep_away`` m of
preferred extra clearance) so paths keep to the middle of corridors where there is room; the grid path
is then shortened by dropping every waypoint whose neighbours see each other with the same clearance.

Approach poses: the dock pose of a slot (:func:`~.footprint.pose_in_front`) backed off along the slot's
facing until the turning circle is clear. The robot reaches the approach pose with the planner and the
follower, then drives straight to the dock pose (docking), and backs straight out to it.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from .footprint import Footprint, pose_in_front, wrap
from .obstacles import FieldObstacles
from .smooth import RADII, SmoothPath, smooth_path

#: m behind an approach pose where a leg may join the slot's normal (:meth:`PathPlanner.plan_to_pose`)
PLAN_TO_POSE_DISTANCES = (0.3, 0.24, 0.19, 0.15, 0.12, 0.09, 0.06)
#: rad: no corner sharper than this at the normal's point (a hairpin: two stops)
PLAN_TO_POSE_MAX_TURN = 2.0
_NEIGHBOURS = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)]


def turn_angle(a, b, c) -> float:
    """rad turned at ``b`` driving from ``a`` through ``b`` to ``c`` ((x, y) each)."""
    h1 = math.atan2(b[1] - a[1], b[0] - a[0])
    h2 = math.atan2(c[1] - b[1], c[0] - b[0])
    return abs(wrap(h2 - h1))


class NoPath(RuntimeError):
    """No collision-free path exists between the two points (for this footprint and margin)."""


@dataclass(frozen=True)
class Path:
    """Waypoints (x, y) in the field frame (m), start first; ``radius`` is the clearance it keeps (m)."""

    points: tuple[tuple[float, float], ...]
    radius: float

    @property
    def length(self) -> float:
        p = np.asarray(self.points)
        return float(np.sum(np.hypot(*np.diff(p, axis=0).T))) if len(p) > 1 else 0.0


class PathPlanner:
    """Plans on ``obstacles`` for a footprint; ``margin`` (m) is added to the footprint's radius."""

    def __init__(self, obstacles: FieldObstacles, margin: float = 0.01, keep_away: float = 0.06,
                 keep_away_weight: float = 4.0):
        self.obstacles = obstacles
        self.margin = float(margin)
        self.keep_away = float(keep_away)
        self.keep_away_weight = float(keep_away_weight)

    def required(self, footprint: Footprint | float) -> float:
        r = footprint if isinstance(footprint, (int, float)) else footprint.radius
        return float(r) + self.margin

    def is_free(self, xy, footprint: Footprint | float) -> bool:
        return self.obstacles.clearance_at(*xy) >= self.required(footprint)

    # ------------------------------------------------------------------------------------------ search
    def plan(self, start, goal, footprint: Footprint | float) -> Path:
        """A smoothed path from ``start`` to ``goal`` ((x, y), m). A start or goal inside the margin (the
        robot docked, or in a tight start corner) is joined to the nearest free cell by a straight line.
        Raises :class:`NoPath`."""
        ob = self.obstacles
        need = self.required(footprint)
        free = ob.clearance >= need
        s = self._nearest_free(ob.cell(*start), free)
        g = self._nearest_free(ob.cell(*goal), free)
        cells = self._astar(s, g, free, need)
        pts = [tuple(start)] + [ob.center(i, j) for i, j in cells] + [tuple(goal)]
        # the start/goal themselves may sit inside the margin: keep them, smooth the rest
        smooth = self._shortcut(pts[1:-1], need)
        out = [tuple(map(float, start))]
        for p in smooth + [tuple(map(float, goal))]:
            if math.hypot(p[0] - out[-1][0], p[1] - out[-1][1]) > 1e-6:
                out.append(p)
        out = self._drop_joins(out, need)
        out = self._drop_short(out, need - self.margin)
        return Path(tuple(out), need)

    def _drop_short(self, pts: list, radius: float, short: float = 0.03) -> list:
        """Drop inner waypoints closer than ``short`` m to the previous one (grid snapping near a start
        inside the margin) when the line that replaces them clears ``radius`` (the footprint's own)."""
        k = 1
        while k < len(pts) - 1:
            a, b = pts[k - 1], pts[k]
            if math.hypot(b[0] - a[0], b[1] - a[1]) < short and self.obstacles.segment_clear(a, pts[k + 1], radius):
                del pts[k]
            else:
                k += 1
        return pts

    def escape_point(self, xy, footprint: Footprint | float) -> tuple[float, float] | None:
        """The nearest point whose clearance fits ``footprint`` (no distance limit), None when ``xy`` is free
        already: where a robot pushed into a corner (farther than :meth:`plan` joins) drives first."""
        ob = self.obstacles
        free = ob.clearance >= self.required(footprint)
        cell = ob.cell(*xy)
        if free[cell]:
            return None
        return tuple(map(float, ob.center(*self._nearest_free(cell, free, max_dist=math.inf))))

    def escape_straight(self, pose, footprint: Footprint, max_dist: float = 0.3,
                        step: float = 0.01) -> tuple[float, float] | None:
        """The nearest point straight ahead of or behind ``pose`` (x, y, heading) whose clearance fits
        ``footprint``, reached without a turn: the exact outline, keeping the heading, touches nothing on the way
        (from ``step`` on: the robot may touch something where it stands); None when there is none within
        ``max_dist`` m or ``pose`` is free already. For a robot that should not turn on the spot where it is (a
        part on the magnet, too close to something)."""
        ob = self.obstacles
        x, y, h = (float(v) for v in pose[:3])
        if self.is_free((x, y), footprint):
            return None
        c, s = math.cos(h), math.sin(h)
        blocked = {1.0: False, -1.0: False}
        for k in range(1, int(round(max_dist / step)) + 1):
            d = k * step
            for sign in (1.0, -1.0):
                if blocked[sign]:
                    continue
                px, py = x + sign * d * c, y + sign * d * s
                if ob.collides(footprint, (px, py, h)):
                    blocked[sign] = True
                elif self.is_free((px, py), footprint):
                    return px, py
            if all(blocked.values()):
                return None
        return None

    def _nearest_free(self, cell, free: np.ndarray, max_dist: float = 0.1) -> tuple[int, int]:
        """The free cell nearest ``cell``; NoPath when there is none within ``max_dist`` m."""
        if free[cell]:
            return cell
        idx = np.argwhere(free)
        if len(idx) == 0:
            raise NoPath("no free cell on the map for this footprint")
        d = np.hypot(idx[:, 0] - cell[0], idx[:, 1] - cell[1])
        k = int(np.argmin(d))
        if d[k] * self.obstacles.resolution > max_dist:
            raise NoPath(f"point {self.obstacles.center(*cell)} is {d[k] * self.obstacles.resolution:.2f} m "
                         "from any free cell")
        return int(idx[k, 0]), int(idx[k, 1])

    def _astar(self, s, g, free: np.ndarray, need: float) -> list[tuple[int, int]]:
        """The grid search from cell ``s`` to ``g``, remembered on the obstacles (which never change): a decision
        plans the same legs several times over (timing each destination, then the leg it chose)."""
        ob = self.obstacles
        key = (s, g, need, self.keep_away, self.keep_away_weight)
        found = ob.searches.get(key)
        if found is None:
            try:
                found = tuple(self._search(s, g, free, need))
            except NoPath as e:
                found = e
            ob.remember(key, found)
        if isinstance(found, NoPath):
            raise NoPath(str(found))
        return list(found)

    def _search(self, s, g, free: np.ndarray, need: float) -> list[tuple[int, int]]:
        """A* over the free cells, 8-connected; a step into a cell with less than ``need + keep_away`` of
        clearance costs more (``keep_away_weight``). Cells are flat indices into the grid padded by one
        non-free cell all round (no bounds checks); the arithmetic and the heap's order are those of (i, j)."""
        ob = self.obstacles
        res = ob.resolution
        pref = need + self.keep_away
        w = self.keep_away_weight
        nx, ny = free.shape
        W = ny + 2
        padded = np.zeros((nx + 2, W), dtype=bool)
        padded[1:-1, 1:-1] = free
        # a step's cost factor into each free cell that keeps less than pref clear (else None: the plain step)
        short = (pref - ob.clearance).ravel()
        near = np.flatnonzero((short > 0) & free.ravel())
        factors = [None] * ((nx + 2) * W)
        for k, f in zip(((near // ny + 1) * W + near % ny + 1).tolist(),
                        (1.0 + w * short[near] / self.keep_away).tolist()):
            factors[k] = f
        is_free = padded.ravel().tolist()
        moves = [(di * W + dj, res * (1.4142135623730951 if di and dj else 1.0)) for di, dj in _NEIGHBOURS]
        start, goal = (s[0] + 1) * W + s[1] + 1, (g[0] + 1) * W + g[1] + 1
        gx, gy = g
        best = [math.inf] * len(is_free)
        best[start] = 0.0
        parent = [-1] * len(is_free)
        parent[start] = start
        heap = [(0.0, 0.0, start)]
        pop, push, hypot = heapq.heappop, heapq.heappush, math.hypot
        while heap:
            _, cost, c = pop(heap)
            if c == goal:
                break
            if cost > best[c]:
                continue
            for dk, base in moves:
                k = c + dk
                if not is_free[k]:
                    continue
                f = factors[k]
                nc = cost + (base if f is None else base * f)
                if nc < best[k]:
                    best[k] = nc
                    parent[k] = c
                    i, j = divmod(k, W)
                    push(heap, (nc + res * hypot(i - 1 - gx, j - 1 - gy), nc, k))
        if parent[goal] < 0:
            raise NoPath(f"no path from {ob.center(*s)} to {ob.center(*g)} with clearance {need:.3f} m")
        out = [goal]
        while out[-1] != start:
            out.append(parent[out[-1]])
        return [(k // W - 1, k % W - 1) for k in reversed(out)]

    def _shortcut(self, pts: list, need: float) -> list:
        """Greedy string pulling: from each kept point, jump to the farthest point it sees (remembered with the
        searches: the same search's cells are pulled the same way)."""
        if len(pts) <= 2:
            return list(pts)
        key = ("shortcut", tuple(pts), need)
        found = self.obstacles.searches.get(key)
        if found is None:
            found = self.obstacles.remember(key, tuple(self._pull(pts, need)))
        return list(found)

    def _pull(self, pts: list, need: float) -> list:
        out = [pts[0]]
        i = 0
        while i < len(pts) - 1:
            j = len(pts) - 1
            while j > i + 1 and not self.obstacles.segment_clear(pts[i], pts[j], need):
                j -= 1
            out.append(pts[j])
            i = j
        return out

    def _drop_joins(self, pts: list, need: float) -> list:
        """Drop a waypoint next to the start or goal when its neighbours see each other."""
        changed = True
        while changed and len(pts) > 2:
            changed = False
            for k in (1, len(pts) - 2):
                if 0 < k < len(pts) - 1 and self.obstacles.segment_clear(pts[k - 1], pts[k + 1], need):
                    del pts[k]
                    changed = True
                    break
        return pts

    # ------------------------------------------------------------------------------------------ smoothing
    def smooth(self, path: Path, footprint: Footprint, final_straight: float = 0.0,
               inflate: float = 0.012, min_radius: float = 0.0, final_min_radius: float = 0.0) -> SmoothPath:
        """``path`` with its corners rounded into arcs (:func:`~.smooth.smooth_path`) wherever the robot's
        exact outline, grown by ``inflate`` m and heading along the arc, stays clear of every obstacle and
        within the floor's allowance. Where the turning circle is clear (the grid) the outline is too."""
        fp = footprint.inflated(inflate)
        need = footprint.radius + inflate
        ob = self.obstacles
        pts = list(path.points)
        # a short first leg (the start snapped to the grid) is dropped where the straight line replacing it
        # is clear for the exact outline: the robot turns in place once, at the start
        while len(pts) > 2 and math.hypot(pts[1][0] - pts[0][0], pts[1][1] - pts[0][1]) < 0.04 \
                and self.straight_clear(pts[0], pts[2], footprint, inflate):
            del pts[1]

        def arc_clear(xy, psi) -> bool:
            near = ob.clearance_of(xy[:, 0], xy[:, 1]) < need  # only there can the exact outline touch anything
            return not ob.collides_poses(fp, xy[near, 0], xy[near, 1], np.asarray(psi)[near])

        return smooth_path(pts, arc_clear, final_straight=final_straight, final_min_radius=final_min_radius,
                           radii=tuple(r for r in RADII if r >= min_radius))

    def plan_to_pose(self, start, goal, footprint: Footprint, distances=PLAN_TO_POSE_DISTANCES,
                     turn_cost: float = 0.08, max_turn: float = PLAN_TO_POSE_MAX_TURN, join_inflate: float = 0.0,
                     arc_join: float = 0.0, path: Path | None = None) -> tuple[Path, bool]:
        """A path from ``start`` (x, y) to the approach pose ``goal`` (x, y, theta facing the slot) whose last
        leg runs along the slot's normal from a point ``d`` m behind ``goal`` (one of ``distances`` whose
        turning circle and line to ``goal`` are clear), so the robot arrives aligned and docking follows on
        without a turn. One A* search to ``goal``; the normal's point is joined to the latest point of that
        path that sees it, the choice the shortest (plus ``turn_cost`` m per radian of corner; no corner of more
        than ``max_turn`` rad at the normal's point, a hairpin). ``join_inflate`` > 0 (m): the straight line to the
        normal's point may also be one along which only the exact outline, grown by that much and heading along
        it, is clear (the robot turns only at its ends, whose turning circles are clear). ``arc_join`` > 0 (m,
        with ``join_inflate``): the normal's point may also be one whose turning circle is not clear, where the
        exact outline grown by that much, facing the slot, is clear from it to ``goal``; the robot must then
        round that corner on an arc (the caller smooths the path and checks it: :meth:`corner_rounded`). Returns
        the path and whether it ends along the normal (False: the plain path to ``goal``; turn there). ``path``:
        the search's result if the caller has it already (the same ``start``, ``goal`` and ``footprint``)."""
        need = self.required(footprint)
        path = path if path is not None else self.plan(start, goal[:2], footprint)
        pts = list(path.points)
        ob = self.obstacles
        bx, by = -math.cos(goal[2]), -math.sin(goal[2])  # away from the slot
        cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(np.asarray(pts), axis=0).T))])

        best = None
        for d in distances:
            pre = (goal[0] + d * bx, goal[1] + d * by)
            # the approach pose's own circle is just clear (5 mm steps): the grid's bound is a few mm short
            if not (self.is_free(pre, footprint) and ob.segment_clear(pre, goal[:2], need - 0.006)) and not (
                    arc_join > 0 and join_inflate > 0
                    and self.straight_clear(pre, goal[:2], footprint, arc_join)):
                continue
            for i in range(len(pts) - 2, -1, -1):
                r = need if i > 0 else need - self.margin  # the start may sit inside the margin
                if math.hypot(pts[i][0] - pre[0], pts[i][1] - pre[1]) < 1e-6 or ob.segment_clear(pts[i], pre, r) or (
                        join_inflate > 0 and self.straight_clear(pts[i], pre, footprint, join_inflate)):
                    if math.hypot(pts[i][0] - pre[0], pts[i][1] - pre[1]) > 1e-6 and \
                            turn_angle(pts[i], pre, goal[:2]) > max_turn:
                        continue  # a hairpin at the normal's point (two stops): worse than a final turn
                    cost = cum[i] + math.hypot(pts[i][0] - pre[0], pts[i][1] - pre[1]) + d
                    cost += turn_cost * turn_angle(pts[i], pre, goal[:2])
                    if i > 0:
                        cost += turn_cost * turn_angle(pts[i - 1], pts[i], pre)
                    if best is None or cost < best[0]:
                        best = (cost, i, pre)
        if best is None:
            return path, False
        _, i, pre = best
        out = pts[:i + 1]
        if math.hypot(out[-1][0] - pre[0], out[-1][1] - pre[1]) > 1e-6:
            out.append(pre)
        out.append(tuple(goal[:2]))
        return Path(tuple(out), path.radius), True

    @staticmethod
    def corner_rounded(path: Path, smooth: SmoothPath) -> bool:
        """True when the smoothed ``path`` does not stop at its last corner (the normal's point of
        :meth:`plan_to_pose`): no piece of ``smooth`` starts there."""
        pts = path.points
        if len(pts) < 3:
            return True
        cx, cy = pts[-2]
        return all(math.hypot(p.xy[0][0] - cx, p.xy[0][1] - cy) > 1e-3 for p in smooth.pieces[1:])

    def straight_clear(self, a, b, footprint: Footprint, inflate: float = 0.012) -> bool:
        """The exact outline (grown by ``inflate``) heading from ``a`` to ``b`` is clear all along the line."""
        fp = footprint.inflated(inflate)
        need = footprint.radius + inflate
        h = math.atan2(b[1] - a[1], b[0] - a[0])
        n = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / 0.01) + 1)
        u = np.arange(n) / (n - 1)
        x, y = a[0] + u * (b[0] - a[0]), a[1] + u * (b[1] - a[1])
        near = self.obstacles.clearance_of(x, y) < need  # only there can the exact outline touch anything
        return not self.obstacles.collides_any(fp, x[near], y[near], h)

    def swept_clear(self, a, b, footprint: Footprint, inflate: float = 0.012) -> bool:
        """:meth:`straight_clear` exactly, not sampled: the area the outline (grown by ``inflate``) sweeps moving
        from ``a`` to ``b`` heading along the line (per rectangle, the convex hull of where it starts and ends)
        overlaps nothing and stays on the floor. A few polygons, whatever the length: for checking many lines."""
        return not self.obstacles.sweep_collides(footprint.inflated(inflate), a, b)

    # ------------------------------------------------------------------------------------------ slots
    def approach_pose(self, slot, dock_distance: float, footprint: Footprint | float,
                      step: float = 0.005, limit: float = 0.4) -> tuple[float, float, float]:
        """The pose (x, y, theta) in front of ``slot`` facing its plate, the nearest to the dock pose
        (``dock_distance`` m from the slot centre) whose turning circle is clear. Raises NoPath."""
        d = dock_distance
        while d <= dock_distance + limit:
            pose = pose_in_front(slot, d)
            if self.is_free(pose[:2], footprint):
                return pose
            d += step
        raise NoPath(f"no clear approach pose in front of {slot.name} within {limit} m of its dock pose")
