"""Legs through one grid point (``legs.via_grid``): the grid search's shortest path is not the fastest one with a
part on the magnet, which turns at most at ``carry.w_max``. A leg that turns one way only (over a machine, not
in an S between them) can be seconds faster though longer: carrying from incoming 4 to outgoing 4 in round 1,
8.1 s by the planner's path, 5.6 s over machine B (the follower's kinematic run, :meth:`.LegPlanner.leg_time`).

:func:`via_candidates` builds legs ``pose -> grid point -> a point of the slot's normal -> the approach pose``,
cheapest first by a lower bound of their time, and returns them with an estimate of their time
(:meth:`.PathFollower.estimate`); the leg planner runs the best few through the follower and keeps one only if
it beats its own leg (:meth:`.LegPlanner.plan`). Empty legs gain less (the empty robot turns at 3 rad/s) but
some (0-1.1 s a leg). The rules are the planner's own:

* each straight line keeps the turning circle clear, or (carrying, ``join_inflate`` > 0) the exact outline grown
  by ``join_inflate`` is clear along it (:meth:`.PathPlanner.swept_clear`), as the planner's join onto the
  normal may;
* the grid point's turning circle is clear (the robot may stop and turn there), and so is the normal's point's,
  whose line to the approach pose is clear (:meth:`.PathPlanner.plan_to_pose`, ``PLAN_TO_POSE_DISTANCES``);
* the smoothed leg rounds the corner at the normal's point (no stop there: it arrives along the normal at the
  docking's entry speed), its arcs checked against the exact outline (:meth:`.PathPlanner.smooth`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .follower import DriveLimits, PathFollower
from .footprint import Footprint
from .planner import PLAN_TO_POSE_DISTANCES, PLAN_TO_POSE_MAX_TURN, Path, PathPlanner, turn_angle
from .smooth import MIN_TURN, SmoothPath

#: legs through grid points built and estimated at most, per leg (the cheapest bound first)
VIA_MAX_TRIES = 12
#: s an estimate may exceed the time to beat and still be built (the estimate leaves the feedback out)
VIA_SLACK = 0.3


@dataclass(frozen=True)
class ViaLeg:
    """A leg through a grid point: the polyline (pose, grid point, normal's point, approach pose ``goal``), the
    smoothed path and the estimated seconds (driving and the docking approach)."""

    path: Path
    smooth: SmoothPath
    goal: tuple
    estimate: float


def via_candidates(pl: PathPlanner, fp: Footprint, limits: DriveLimits, dt: float, pose, goals, *, step: float,
                   join: float, beat: float, end_speed: float, tail: Callable[[tuple], float],
                   smoothed: Callable[[Path], SmoothPath], final_straight: float,
                   final_min_radius: float) -> list[ViaLeg]:
    """Legs from ``pose`` (x, y, heading) to one of ``goals`` (approach poses) through a grid point ``step`` m
    apart whose estimated time is under ``beat`` s (+ ``VIA_SLACK``), best estimate first. ``tail(goal)``: s of
    the docking approach after it; ``smoothed(path)``: the planner's smoothing of a leg along the normal, whose
    last corner needs ``final_min_radius`` before ``final_straight`` m of line; ``join``: the exact outline's
    growth for a line whose turning circle is not clear (0: the turning circle everywhere)."""
    ob = pl.obstacles
    need = pl.required(fp)
    x, y, th = (float(v) for v in pose[:3])
    (fx0, fx1), (fy0, fy1) = ob.field.floor.x, ob.field.floor.y
    X, Y = (a.ravel() for a in np.meshgrid(np.arange(fx0 + step / 2, fx1, step), np.arange(fy0 + step / 2, fy1, step),
                                            indexing="ij"))
    keep = ob.clearance_of(X, Y) >= need
    XY = np.stack((X[keep], Y[keep]), axis=-1)
    to_via = np.hypot(XY[:, 0] - x, XY[:, 1] - y) / limits.v_max + np.abs(
        (np.arctan2(XY[:, 1] - y, XY[:, 0] - x) - th + math.pi) % (2 * math.pi) - math.pi) / limits.w_max
    pairs = []  # (bound s, grid point, goal, normal's point, its distance from the goal)
    for g in goals:
        for d in PLAN_TO_POSE_DISTANCES:
            pre = (g[0] - d * math.cos(g[2]), g[1] - d * math.sin(g[2]))
            if pl.is_free(pre, fp) and ob.segment_clear(pre, g[:2], need - 0.006):
                bound = to_via + (np.hypot(pre[0] - XY[:, 0], pre[1] - XY[:, 1]) + d) / limits.v_max + tail(g)
                pairs += [(float(bound[k]), int(k), g, pre, d) for k in np.flatnonzero(bound < beat + VIA_SLACK)]
    pairs.sort(key=lambda p: p[0])
    XY = XY[sorted({p[1] for p in pairs})] if pairs else XY[:0]  # (only the grid points some pair has)
    index = {k: i for i, k in enumerate(sorted({p[1] for p in pairs}))}
    inner = fp.inflated(join).inner if join > 0 else math.inf  # (a line nearer anything: the outline touches it)
    least: dict = {}  # per end point: the least clearance of the line from it to each grid point
    swept: dict = {}

    def line_clear(a, i: int, circle: float) -> bool:  # the line between a and grid point i
        if a not in least:
            least[a] = ob.segments_clearance(a, XY)
        if least[a][i] >= circle:
            return True
        if least[a][i] < inner:
            return False
        if (a, i) not in swept:
            swept[a, i] = pl.swept_clear(a, tuple(XY[i]), fp, join)
        return swept[a, i]

    estimator = PathFollower(limits, dt)
    best = beat + VIA_SLACK
    found, tries = [], 0
    for bound, k, g, pre, d in pairs:
        if bound >= best or tries >= VIA_MAX_TRIES:
            break
        k = index[k]
        v = (float(XY[k, 0]), float(XY[k, 1]))
        phi = turn_angle(v, pre, g)
        if phi > PLAN_TO_POSE_MAX_TURN or (  # (no arc would fit before the straight line: a stop there)
                phi >= MIN_TURN and final_min_radius * math.tan(phi / 2) > d - final_straight):
            continue
        # (the start may sit inside the margin, as the planner allows; the normal's point may not)
        if not (line_clear((x, y), k, need - pl.margin) and line_clear(pre, k, need)):
            continue
        path = Path(((x, y), v, pre, tuple(g[:2])), need)
        sp = smoothed(path)
        if not pl.corner_rounded(path, sp):
            continue
        tries += 1
        est = estimator.estimate(sp, th, end_speed) + tail(g)
        if est < best:
            best = est
            found.append(ViaLeg(path, sp, g, est))
    return sorted(found, key=lambda f: f.estimate)
