"""Paths for carrying a part: forward and reverse arcs no tighter than a radius, never a turn on the spot
(hybrid A* over (x, y, heading)).

Why: SimTwo's electromagnet holds a part with a finite pull (5 N) and the friction of its face; turning on
the spot drags the part round over the floor and it slides off the magnet, while arcs at speed keep it
(docs/simulator.md, "The electromagnet"). So a loaded robot changes heading only while it drives, and it
may drive backwards (a change of direction is a stop, not a turn): leaving a warehouse slot it backs out on
an arc, stops, and drives forward to the destination, as a car would.

The search: states (x, y, theta) binned at ``xy_bin`` m and ``heading_bins`` per turn; each expansion
drives ``step`` m forwards at curvature -1/R, 0 or +1/R (``radius`` R) or straight backwards (backwards
arcs too with ``reverse_arcs``); a state is free when
the robot's outline (carrying, grown by ``inflate``), covered by ``circles`` circles along its length,
keeps clear of every obstacle on the clearance grid (a lower bound of the distance: conservative); cost = length, backwards
``reverse_cost`` times, plus ``switch_cost`` m per change of direction and ``turn_cost`` m per change of
curvature; heuristic = the grid distance to the goal (Dijkstra over cells where the robot's half-width
fits, :class:`~.obstacles.FieldObstacles`' clearance). The goal is reached within ``goal_xy`` m and
``goal_heading`` rad; the follower's feedback takes the rest on the straight line that follows.

Output: a :class:`~.smooth.SmoothPath` whose pieces are the stretches of one direction (``Piece.reverse``),
sampled every ``ds`` m with the heading of the motion and its curvature.
"""
from __future__ import annotations

import heapq
import math

import numpy as np

from .footprint import Footprint, wrap
from .obstacles import FieldObstacles
from .smooth import Piece, SmoothPath


class NoCarryPath(RuntimeError):
    """No path of arcs found within the search's limits."""


class CarryPlanner:
    """Hybrid A* for one footprint on one obstacle map (see the module docstring)."""

    def __init__(self, obstacles: FieldObstacles, footprint: Footprint, radius: float = 0.2, step: float = 0.06,
                 xy_bin: float = 0.03, heading_bins: int = 48, inflate: float = 0.008, reverse_cost: float = 1.3,
                 switch_cost: float = 0.25, turn_cost: float = 0.01, goal_xy: float = 0.02,
                 goal_heading: float = 0.1, max_expansions: int = 12000, circles: int = 4,
                 reverse_arcs: bool = False, shot_every: int = 10):
        self.ob = obstacles
        self.fp = footprint.inflated(inflate)
        self.r_need = footprint.radius + inflate
        self.radius, self.step = float(radius), float(step)
        self.xy_bin, self.nh = float(xy_bin), int(heading_bins)
        self.reverse_cost, self.switch_cost, self.turn_cost = reverse_cost, switch_cost, turn_cost
        self.goal_xy, self.goal_heading = goal_xy, goal_heading
        self.max_expansions = max_expansions
        self.shot_every = int(shot_every)
        self.expansions = 0
        half_width = max(max(abs(r.y0), abs(r.y1)) for r in footprint.rects)
        self._lane = half_width + 0.005  # where the robot fits driving along (the heuristic's grid)
        self.circles = [(cx, r + inflate) for cx, r in covering_circles(footprint, circles)]
        # SimTwo's magnet keeps a part on forward arcs of 0.15 m and more, loses it on backward arcs of any
        # radius and on turns on the spot (measured on the stand-in, docs/agent.md): forward arcs, straight back
        self.primitives = [(1, 0.0), (1, 1.0 / self.radius), (1, -1.0 / self.radius)] + \
            [(-1, 0.0)] + ([(-1, 1.0 / self.radius), (-1, -1.0 / self.radius)] if reverse_arcs else [])

    # ------------------------------------------------------------------------------------------ checks
    def free(self, x: float, y: float, th: float) -> bool:
        """The outline, covered by circles along its length, clear (the grid's lower bound: conservative)."""
        c, s = math.cos(th), math.sin(th)
        for cx, r in self.circles:
            if self.ob.clearance_at(x + cx * c, y + cx * s) < r:
                return False
        return True

    def _heuristic_grid(self, goal) -> np.ndarray:
        """Distance (m) from every cell to the goal's cell over cells with clearance >= the half-width."""
        ob = self.ob
        free = ob.clearance >= self._lane
        dist = np.full(free.shape, np.inf)
        g = ob.cell(*goal[:2])
        dist[g] = 0.0
        heap = [(0.0, g)]
        res = ob.resolution
        nx, ny = free.shape
        while heap:
            d, (i, j) = heapq.heappop(heap)
            if d > dist[i, j]:
                continue
            for di, dj, c in ((1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0), (1, 1, 1.4142), (1, -1, 1.4142),
                              (-1, 1, 1.4142), (-1, -1, 1.4142)):
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny and free[a, b]:
                    nd = d + c * res
                    if nd < dist[a, b]:
                        dist[a, b] = nd
                        heapq.heappush(heap, (nd, (a, b)))
        return dist

    # ------------------------------------------------------------------------------------------ search
    def plan(self, start, goal, ds: float = 0.01) -> SmoothPath:
        """From ``start`` to ``goal`` (both (x, y, theta), m, rad). Raises :class:`NoCarryPath`."""
        h = self._heuristic_grid(goal)
        R, L = self.radius, self.step
        prims = self.primitives
        hb = 2 * math.pi / self.nh

        def key(s):
            return (int(math.floor(s[0] / self.xy_bin)), int(math.floor(s[1] / self.xy_bin)),
                    int(round(s[2] / hb)) % self.nh)

        def hcost(s):
            v = h[self.ob.cell(s[0], s[1])]
            return max(v, math.hypot(s[0] - goal[0], s[1] - goal[1])) if math.isfinite(v) else 10.0

        s0 = (float(start[0]), float(start[1]), float(start[2]))
        nodes = [(s0, None, None)]  # state, parent index, primitive
        best = {key(s0): 0.0}
        heap = [(hcost(s0), 0.0, 0, 0)]
        done = None
        shot = None
        n = 0
        while heap:
            _, g, idx, _ = heapq.heappop(heap)
            s, parent, prim = nodes[idx]
            if g > best.get(key(s), math.inf) + 1e-9:
                continue
            if math.hypot(s[0] - goal[0], s[1] - goal[1]) <= self.goal_xy and \
                    abs(wrap(s[2] - goal[2])) <= self.goal_heading:
                done = idx
                break
            n += 1
            if n > self.max_expansions:
                break
            if n % self.shot_every == 1 or hcost(s) < 0.4:  # try to reach the goal exactly: a Dubins path
                shot = self._dubins_shot(s, goal)
                if shot is not None:
                    done = idx
                    break
            for d, k in prims:
                ok, t = self._drive(s, d, k, L)
                if not ok:
                    continue
                c = L * (1.0 if d > 0 else self.reverse_cost)
                if prim is not None and prim[0] != d:
                    c += self.switch_cost
                if prim is not None and prim[1] != k:
                    c += self.turn_cost
                ng = g + c
                kk = key(t)
                if ng < best.get(kk, math.inf) - 1e-9:
                    best[kk] = ng
                    nodes.append((t, idx, (d, k)))
                    heapq.heappush(heap, (ng + hcost(t), ng, len(nodes) - 1, 0))
        if done is None:
            raise NoCarryPath(f"no path of arcs (radius {R:.2f} m) from ({s0[0]:.2f}, {s0[1]:.2f}) to "
                              f"({goal[0]:.2f}, {goal[1]:.2f}) within {self.max_expansions} expansions")
        chain = []
        i = done
        while nodes[i][1] is not None:
            chain.append((nodes[nodes[i][1]][0], nodes[i][2], self.step))
            i = nodes[i][1]
        chain.reverse()
        if shot is not None:
            chain += shot
        self.expansions = n
        return self._pieces(chain, ds)

    def _dubins_shot(self, s, goal):
        """The shortest forward Dubins path (arc, line, arc of radius R) from ``s`` to ``goal`` that is clear,
        as [(state, (1, k), length)]; None if none is."""
        for length, segs in dubins_words(s, goal, self.radius):
            out = []
            st = s
            ok = True
            for k, L in segs:
                if L <= 1e-9:
                    continue
                n = max(1, int(math.ceil(L / 0.03)))
                for i in range(1, n + 1):
                    if not self.free(*_arc(st, 1, k, L * i / n)):
                        ok = False
                        break
                if not ok:
                    break
                out.append((st, (1, k), L))
                st = _arc(st, 1, k, L)
            if ok:
                return out
        return None

    def _drive(self, s, d: int, k: float, L: float):
        """The state after driving ``L`` m in direction ``d`` at curvature ``k``; and whether the outline is
        clear along it (checked at its middle and end)."""
        mid = _arc(s, d, k, L / 2)
        end = _arc(s, d, k, L)
        return self.free(*mid) and self.free(*end), end

    def _pieces(self, chain, ds: float) -> SmoothPath:
        pieces = []
        cur = []  # samples (x, y, psi, kappa) of the current direction
        cur_d = None
        for s, (d, k), length in chain:
            n = max(1, int(math.ceil(length / ds)))
            pts = [_arc(s, d, k, length * i / n) for i in range(n + 1)]
            if cur_d is not None and d != cur_d:
                pieces.append(_piece(cur, cur_d))
                cur = []
            cur_d = d
            for j, p in enumerate(pts):
                if cur and j == 0:
                    continue
                psi = p[2] if d > 0 else wrap(p[2] + math.pi)
                cur.append((p[0], p[1], psi, k * d))
        if cur:
            pieces.append(_piece(cur, cur_d))
        return SmoothPath(tuple(pieces))


def dubins_words(s, g, R: float):
    """Forward paths of radius ``R`` from pose ``s`` to pose ``g`` ((x, y, theta)): the words LSL, RSR, LSR,
    RSL that exist, shortest first, each as (length, [(curvature, length) x 3])."""
    two_pi = 2 * math.pi

    def centre(p, side):  # side +1: the circle to the left
        return p[0] - side * R * math.sin(p[2]), p[1] + side * R * math.cos(p[2])

    out = []
    for a, b in ((1, 1), (-1, -1), (1, -1), (-1, 1)):
        c1, c2 = centre(s, a), centre(g, b)
        dx, dy = c2[0] - c1[0], c2[1] - c1[1]
        D = math.hypot(dx, dy)
        psi = math.atan2(dy, dx)
        if a == b:
            phi, line = psi, D
        else:
            if D < 2 * R:
                continue
            line = math.sqrt(D * D - 4 * R * R)
            phi = psi + a * math.atan2(2 * R, line)
        t1 = ((phi - s[2]) * a) % two_pi  # left: the heading grows
        t2 = ((g[2] - phi) * b) % two_pi
        out.append((R * t1 + line + R * t2, [(a / R, R * t1), (0.0, line), (b / R, R * t2)]))
    out.sort(key=lambda w: w[0])
    return out


def covering_circles(fp: Footprint, n: int) -> list[tuple[float, float]]:
    """``n`` circles (x of the centre on base_link's x axis, radius; m) that together cover the outline:
    its length cut into ``n`` equal slabs, each circle centred on its slab, through the slab's farthest
    corner."""
    x0, x1 = fp.back, fp.front
    w = (x1 - x0) / n
    out = []
    for i in range(n):
        a, b = x0 + i * w, x0 + (i + 1) * w
        cx = (a + b) / 2
        r = 0.0
        for rect in fp.rects:
            lo, hi = max(a, rect.x0), min(b, rect.x1)
            if lo > hi:
                continue
            for x in (lo, hi):
                for y in (rect.y0, rect.y1):
                    r = max(r, math.hypot(x - cx, y))
        if r > 0.0:
            out.append((cx, r))
    return out


def _arc(s, d: int, k: float, L: float) -> tuple[float, float, float]:
    """(x, y, theta) after ``L`` m in direction ``d`` (+1 forward, -1 back) at curvature ``k`` (turn of the
    heading per metre driven forward)."""
    x, y, th = s
    sl = d * L
    if abs(k) < 1e-9:
        return x + sl * math.cos(th), y + sl * math.sin(th), th
    th2 = th + k * sl
    return x + (math.sin(th2) - math.sin(th)) / k, y - (math.cos(th2) - math.cos(th)) / k, wrap(th2)


def _piece(samples, d: int) -> Piece:
    a = np.asarray(samples, dtype=float)
    xy = a[:, :2]
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    return Piece(xy, s, np.unwrap(a[:, 2]), a[:, 3], reverse=d < 0)
