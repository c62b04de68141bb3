"""Smooth paths for a differential-drive robot: a polyline's corners rounded into circular arcs (fillets),
sampled densely with heading and curvature, so the robot turns while it drives instead of stopping at
every corner.

A :class:`SmoothPath` is a list of :class:`Piece` s. Within a piece the heading is continuous (straight
lines and arcs); between two pieces the robot stops and turns in place (a corner that could not be
rounded). Frames and units: the field frame, metres, radians; curvature in 1/m, left turns positive.

:func:`smooth_path` rounds each corner with the largest radius of ``radii`` whose arc fits between the
neighbouring corners and passes ``arc_clear(xy, heading)`` (the planner's exact check of the robot's
outline along the arc); without ``arc_clear`` an arc may deviate at most ``max_deviation`` m from the
corner it replaces (a path given as a bare polyline, e.g. backing out, stays on its line).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .footprint import wrap

RADII = (0.6, 0.45, 0.35, 0.27, 0.2, 0.15, 0.11, 0.08, 0.06, 0.045, 0.035)  # m, tried largest first
MIN_TURN = 0.2  # rad: a corner without an arc turning more than this is a stop (less: driven through on its line)


@dataclass(frozen=True)
class Piece:
    """A path without a stop: samples ``xy`` (N x 2), arc length ``s`` (N, from the piece's start),
    heading ``psi`` (N) and curvature ``kappa`` (N) at each sample."""

    xy: np.ndarray
    s: np.ndarray
    psi: np.ndarray  # the direction of motion (the robot's heading + pi on a piece driven backwards)
    kappa: np.ndarray  # of the motion's direction, per metre
    reverse: bool = False  # driven backwards (the robot's back first)

    @property
    def length(self) -> float:
        return float(self.s[-1]) if len(self.s) else 0.0

    def at(self, s: float) -> tuple[float, float, float, float]:
        """(x, y, psi, kappa) at arc length ``s`` (clipped to the piece); linear between samples."""
        s = min(max(s, 0.0), self.length)
        i = int(np.searchsorted(self.s, s, side="right")) - 1
        i = min(max(i, 0), len(self.s) - 2) if len(self.s) > 1 else 0
        if len(self.s) == 1:
            return float(self.xy[0, 0]), float(self.xy[0, 1]), float(self.psi[0]), float(self.kappa[0])
        ds = self.s[i + 1] - self.s[i]
        u = 0.0 if ds <= 0 else (s - self.s[i]) / ds
        x, y = self.xy[i] + u * (self.xy[i + 1] - self.xy[i])
        dpsi = wrap(float(self.psi[i + 1] - self.psi[i]))
        return float(x), float(y), float(self.psi[i] + u * dpsi), float(self.kappa[i] + u * (self.kappa[i + 1] - self.kappa[i]))


@dataclass(frozen=True)
class SmoothPath:
    """Pieces driven one after the other; the robot stops and turns in place between them."""

    pieces: tuple[Piece, ...]

    @property
    def length(self) -> float:
        return sum(p.length for p in self.pieces)

    @property
    def points(self) -> np.ndarray:
        """All samples (M x 2)."""
        return np.concatenate([p.xy for p in self.pieces]) if self.pieces else np.zeros((0, 2))

    @property
    def stops(self) -> int:
        """Corners where the robot stops and turns in place."""
        return max(len(self.pieces) - 1, 0)


def _heading(a, b) -> float:
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _line(a, b, ds: float):
    n = max(1, int(math.ceil(math.hypot(b[0] - a[0], b[1] - a[1]) / ds)))
    u = np.linspace(0.0, 1.0, n + 1)[:, None]
    xy = np.asarray(a, float) + u * (np.asarray(b, float) - np.asarray(a, float))
    return xy, np.full(len(xy), _heading(a, b)), np.zeros(len(xy))


def fillet(corner, h_in: float, h_out: float, r: float, ds: float):
    """The arc of radius ``r`` tangent to the line into ``corner`` (heading ``h_in``) and the line out
    (``h_out``): its samples (xy, psi, kappa) from the tangent point on the way in to the one on the way
    out, and the tangent length (m from the corner)."""
    phi = wrap(h_out - h_in)
    t = r * math.tan(abs(phi) / 2)
    side = 1.0 if phi > 0 else -1.0  # left turn: the centre lies to the left of the way in
    p0 = np.asarray(corner, float) - t * np.array([math.cos(h_in), math.sin(h_in)])
    c = p0 + side * r * np.array([-math.sin(h_in), math.cos(h_in)])
    n = max(2, int(math.ceil(abs(phi) * r / ds)) + 1)
    psi = h_in + np.linspace(0.0, phi, n)
    ang = psi - side * math.pi / 2
    xy = c + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    return xy, psi, np.full(n, side / r), t


def smooth_path(points, arc_clear: Callable[[np.ndarray, np.ndarray], bool] | None = None,
                radii=RADII, ds: float = 0.01, max_deviation: float = 0.003, min_turn: float = MIN_TURN,
                final_straight: float = 0.0, final_min_radius: float = 0.0) -> SmoothPath:
    """Round the corners of the polyline ``points`` ((x, y), m). A corner that turns by more than
    ``min_turn`` rad and gets no arc is a stop (the robot turns in place there); a gentler one without an
    arc is driven through on its line (a kink the follower's feedback takes). ``final_straight`` (m): the
    last segment keeps at least this much straight line before the end (the docking approach), and the
    corner before it gets no arc tighter than ``final_min_radius`` (m): the robot must arrive settled on
    the line, which it does not right after a tight arc (measured: 0.15 rad off 2 cm after r = 0.06 m)."""
    pts = [tuple(map(float, p)) for p in points]
    keep = [pts[0]]
    for p in pts[1:]:
        if math.hypot(p[0] - keep[-1][0], p[1] - keep[-1][1]) > 1e-6:
            keep.append(p)
    pts = keep
    if len(pts) == 1:
        z = np.zeros(1)
        return SmoothPath((Piece(np.array([pts[0]]), z, z.copy(), z.copy()),))
    seg = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(pts[:-1], pts[1:])]
    hd = [_heading(a, b) for a, b in zip(pts[:-1], pts[1:])]
    n = len(seg)
    # per corner k (between segment k-1 and k): the arc chosen, or None
    arcs: list = [None] * (n + 1)
    used_in = [0.0] * n  # tangent length taken from each segment's start
    for k in range(1, n):
        phi = wrap(hd[k] - hd[k - 1])
        if abs(phi) < 1e-4:
            continue
        room_in = seg[k - 1] - used_in[k - 1]
        room_out = (seg[k] - final_straight) if k == n - 1 else seg[k] / 2
        for r in radii:
            if k == n - 1 and r < final_min_radius:
                continue
            t = r * math.tan(abs(phi) / 2)
            if t > room_in + 1e-9 or t > room_out + 1e-9 or abs(phi) > math.pi - 0.05:
                continue
            if arc_clear is None:
                if r * (1.0 / math.cos(abs(phi) / 2) - 1.0) > max_deviation:
                    continue
            xy, psi, kap, t = fillet(pts[k], hd[k - 1], hd[k], r, ds)
            if arc_clear is not None and not arc_clear(xy, psi):
                continue
            arcs[k] = (xy, psi, kap, t)
            used_in[k] = t
            break
    pieces = []
    cur_xy, cur_psi, cur_k = [], [], []

    def add(xy, psi, kap):
        if cur_xy and len(xy) and np.hypot(*(xy[0] - cur_xy[-1][-1])) < 1e-9:
            xy, psi, kap = xy[1:], psi[1:], kap[1:]
        if len(xy):
            cur_xy.append(xy)
            cur_psi.append(psi)
            cur_k.append(kap)

    def close():
        xy = np.concatenate(cur_xy)
        s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
        pieces.append(Piece(xy, s, np.concatenate(cur_psi), np.concatenate(cur_k)))
        cur_xy.clear(), cur_psi.clear(), cur_k.clear()

    start = np.asarray(pts[0])
    for k in range(n):
        end_t = arcs[k + 1][3] if k + 1 < n and arcs[k + 1] is not None else 0.0
        u = np.array([math.cos(hd[k]), math.sin(hd[k])])
        a = start
        b = np.asarray(pts[k + 1]) - end_t * u
        if np.hypot(*(b - a)) > 1e-9:
            add(*_line(a, b, ds))
        elif not cur_xy:
            add(np.array([a]), np.array([hd[k]]), np.zeros(1))
        if k + 1 < n:
            if arcs[k + 1] is not None:
                xy, psi, kap, _ = arcs[k + 1]
                add(xy, psi, kap)
                start = xy[-1]
            else:
                phi = wrap(hd[k + 1] - hd[k])
                if abs(phi) > min_turn:  # a stop: a new piece starts at the corner
                    close()
                start = np.asarray(pts[k + 1])
    close()
    return SmoothPath(tuple(pieces))
