"""Leg planning: "go to this slot, carrying a part or not" turned into a planned, smoothed path, or a failure.

A *leg* is the drive from the robot's pose to a slot's approach pose, after which the docking follows on
(:mod:`.docking`). :class:`LegPlanner` owns what planning needs and does not change: the field, the robot's
outlines (empty and carrying), the dock distance, the settings, the drive limits (for the time a leg takes)
and the docking's entry speeds. What changes during a round comes in as arguments: the obstacles as they are
now (:meth:`LegPlanner.obstacles` from the server's last state, the blocked spots remembered and the slot
left out), the pose, the target slot and whether a part is carried. No side effects: the caller
(:class:`~.behaviour.RoundAgent`) starts the follower on the :class:`LegPlan` and decides what a failure
(:class:`~.planner.NoPath`, :class:`~.hybrid.NoCarryPath`) means.

- :meth:`~LegPlanner.plan`: the usual leg (grid A* to the approach pose, arriving along the slot's normal
  where it can, corners rounded into arcs), or with ``legs.via_grid`` a faster one through a grid point
  (:mod:`.vias`);
- :meth:`~LegPlanner.plan_on_arcs`: a place leg of forward arcs and straight reversing only (``carry.arcs``);
- :meth:`~LegPlanner.leg_time`: the seconds a leg would take (a kinematic run of the follower);
- :meth:`~LegPlanner.escape_point`: the nearest point clear for the outline (a robot too close to something);
- :meth:`~LegPlanner.retreat`: how far from the slot to back out after docking.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .follower import DriveLimits, PathFollower
from .footprint import Footprint, carrying_footprint, dock_distance, robot_footprint
from .hybrid import CarryPlanner, NoCarryPath
from .obstacles import FieldObstacles, PartObstacle, square_polygon
from .planner import NoPath, Path, PathPlanner
from .settings import AgentSettings
from .smooth import Piece, SmoothPath
from .state import ZONES, FactoryState, SlotRef
from .vias import via_candidates

MACHINE_CLEARANCE = 0.2  # m from a machine input after placing (the machine needs > 0.17 m)
BLOCKED_SPOT_SIDE = 0.06  # m, the square a blocked spot becomes on the map


@dataclass(frozen=True)
class Escape:
    """Where a robot too close to something drives first (:meth:`LegPlanner.escape_point`)."""

    xy: tuple[float, float]
    #: on the robot's heading line, ahead or behind, clear all the way: a steering drive ends there; else the
    #: nearest clear point, which may lie beside the robot
    straight: bool


@dataclass(frozen=True)
class LegPlan:
    """A planned leg: the planner's polyline ``path``, what the follower drives (``smooth``: a SmoothPath, or the
    polyline without smoothing), the approach pose ``goal`` (x, y, theta) it ends at, whether it arrives along
    the slot's normal (``aligned``: the docking follows on at ``end_speed`` m/s) and the slot."""

    path: Path
    smooth: object
    goal: tuple
    aligned: bool
    end_speed: float
    slot: object


#: m behind the approach pose: where a leg may join the slot's normal on an arc (legs.arc_join): far enough out for
#: the tightest arc before a place (a right angle at 8 cm) and the straight line after it
ARC_JOIN_DISTANCES = (0.12, 0.15, 0.19, 0.24, 0.3)
#: s a leg through a grid point (legs.via_grid) must save over the planner's leg to be taken instead
VIA_MIN_GAIN = 0.2
#: of the legs through a grid point (:mod:`.vias`), the best estimates timed by the follower's kinematic run
VIA_TIMED = 2
#: of the destinations a decision times by the planner's legs, the fastest this many are searched for a leg through
#: a grid point (each search costs several planned legs: one destination's, not four, holds a real-time robot up)
VIA_RANKED = 2


@dataclass(frozen=True)
class _LegContext:
    """What planning a leg to one slot needs besides the pose: the planner on the obstacles, the outline, the
    slot, the goals (the approach pose, a place's farther one first), the join's inflation, the final straight
    and arc, and the smoothing with them (``smoothed(path, aligned)``)."""

    planner: PathPlanner
    footprint: Footprint
    slot: object
    goals: list
    join: float
    final_straight: float
    final_min_radius: float
    smoothed: Callable


class LegPlanner:
    """Plans legs on one field for one robot (see the module docstring).

    ``limits`` / ``carry_limits``: the follower's limits empty and with a part on the magnet; ``dt``: the
    control period (s); ``entry_speed("pick" | "place")``: the speed (m/s) a leg may arrive at the approach
    pose with when that docking follows on (:meth:`.docking.Docker.entry_speed`)."""

    def __init__(self, field, robot, settings: AgentSettings, limits: DriveLimits, carry_limits: DriveLimits,
                 dt: float, entry_speed: Callable[[str], float]):
        self.field = field
        self.settings = settings
        self.limits = limits
        self.carry_limits = carry_limits
        self.dt = float(dt)
        self.entry_speed = entry_speed
        self.fp_empty = robot_footprint(robot)
        self.fp_carry = carrying_footprint(robot, field.part)
        self.d_dock = dock_distance(robot, field.part)

    def slot(self, target):
        """The slot a leg goes to: ``target`` itself when it is one already (anything with ``xy`` and
        ``facing``: a part lying on the floor, :class:`~.refind.FloorSlot`), else the field's slot of the
        :class:`~.state.SlotRef`."""
        return target if hasattr(target, "xy") else self.field.slot(target.zone, target.number)

    def footprint(self, carrying: bool) -> Footprint:
        """The robot's outline, with a part on the magnet or not."""
        return self.fp_carry if carrying else self.fp_empty

    def obstacles(self, state: FactoryState, blocked=(), exclude: SlotRef | None = None,
                  floor=()) -> FieldObstacles:
        """The field with the parts of ``state`` (but the one in ``exclude``), the parts lying on the floor
        ``floor`` (:class:`~.obstacles.PartObstacle`: lost on the way, which the server does not list) and a
        small square on each blocked spot ``blocked`` ((x, y, ...) in m; the caller drops those it no longer
        remembers)."""
        parts = list(floor)
        for zone in ZONES:
            for n, p in enumerate(state.zone(zone), start=1):
                if p is not None and SlotRef(zone, n) != exclude:
                    s = self.field.slot(zone, n)
                    parts.append(PartObstacle(*s.xy, s.facing))
        return FieldObstacles(self.field, parts,
                              extra=[square_polygon(x, y, BLOCKED_SPOT_SIDE) for x, y, *_ in blocked])

    def path_planner(self, obstacles: FieldObstacles, carrying: bool) -> PathPlanner:
        """A grid planner on ``obstacles`` with the margin of the empty or carrying robot."""
        return PathPlanner(obstacles, margin=self.settings.carry.margin if carrying else 0.01)

    # ------------------------------------------------------------------------------------------ legs
    def plan(self, obstacles: FieldObstacles, pose, target: SlotRef, carrying: bool, dock: str,
             via: bool = True) -> LegPlan:
        """The leg from ``pose`` to ``target``'s approach pose, the ``dock`` ("pick" or "place") following on:
        arriving along the slot's normal where it can (then at the docking's entry speed), else with a turn
        on the spot farther out; with ``legs.via_grid`` (and ``via``) the leg through a grid point instead
        where that is faster (:meth:`faster`). ``target``: a SlotRef, or a slot itself (:meth:`slot`). Raises
        NoPath."""
        ctx = self._context(obstacles, target, carrying)
        pl, fp, goals, join, smoothed = ctx.planner, ctx.footprint, ctx.goals, ctx.join, ctx.smoothed
        lg = self.settings.legs
        if lg.smooth:  # the last leg along the slot's normal: docking follows on at speed
            for g in goals:  # the leg ending farther out if it can arrive along the normal there
                path, aligned = pl.plan_to_pose(tuple(pose[:2]), g, fp, join_inflate=join)
                if aligned:
                    break
            sp = None
            if join > 0 and lg.arc_join > 0:  # onto the normal on an arc where it would stop and turn there
                sp = smoothed(path, aligned)
                if not (aligned and pl.corner_rounded(path, sp)):
                    arc = self._arc_join_leg(pl, pose, goals, fp, join, lg.arc_join, smoothed)
                    if arc is not None:
                        path, g, sp = arc
                        aligned = True
            goal = g if aligned else goals[0]  # not aligned: a turn on the spot farther out
            if not aligned and len(goals) > 1:  # (the loop ended on the last goal)
                path, aligned = pl.plan_to_pose(tuple(pose[:2]), goal, fp, join_inflate=join)
                sp = None
            sp = sp if sp is not None else smoothed(path, aligned)
            end_speed = self.entry_speed(dock) if aligned else 0.0
        else:
            goal = goals[0]
            path, aligned = pl.plan(tuple(pose[:2]), goal[:2], fp), False
            sp, end_speed = path.points, 0.0
        leg = LegPlan(path, sp, goal, aligned, end_speed, ctx.slot)
        if via and lg.smooth and lg.via_grid > 0:
            leg = self._via_leg(ctx, pose, leg, carrying, dock)[0]
        return leg

    def faster(self, obstacles: FieldObstacles, pose, leg: LegPlan, carrying: bool, dock: str,
               seconds: float | None = None) -> tuple[LegPlan, float]:
        """``legs.via_grid``: the leg through a grid point that is faster than ``leg`` (planned from ``pose``
        with ``via`` false, taking ``seconds`` by :meth:`leg_time` if known) and its seconds, or ``leg`` and
        its seconds. A decision that times several destinations plans them without it and asks this for the
        best few: the search costs several planned legs (docs/benchmarks.md, "bench planning")."""
        if not (self.settings.legs.smooth and self.settings.legs.via_grid > 0):
            return leg, seconds if seconds is not None else self.leg_time(leg, pose, carrying)
        return self._via_leg(self._context(obstacles, leg.slot, carrying), pose, leg, carrying, dock, seconds)

    def timed(self, obstacles: FieldObstacles, pose, target, carrying: bool, dock: str) -> tuple[LegPlan, float]:
        """The usual leg (:meth:`plan` without the grid point) and its seconds (:meth:`leg_time`): what a choice
        between several targets compares (:meth:`faster` then improves the chosen one). Raises NoPath."""
        leg = self.plan(obstacles, pose, target, carrying, dock, via=False)
        return leg, self.leg_time(leg, pose, carrying)

    def between(self, obstacles: FieldObstacles, source, target, carrying: bool) -> float:
        """Seconds of the leg from the approach pose in front of ``source`` (where the robot backs out to after
        docking there: after a pick carrying, after a place not) to ``target``, through a grid point where that is
        faster (:meth:`faster`); inf when there is no path. The table of :class:`~.order.LegTimes`."""
        dock = "place" if carrying else "pick"
        try:
            start = self.path_planner(obstacles, carrying).approach_pose(self.slot(source), self.d_dock,
                                                                         self.footprint(carrying))
            leg, seconds = self.timed(obstacles, start, target, carrying, dock)
            return self.faster(obstacles, start, leg, carrying, dock, seconds)[1]
        except NoPath:
            return math.inf

    def _context(self, obstacles: FieldObstacles, target, carrying: bool) -> "_LegContext":
        """What planning a leg to ``target`` needs besides the pose (:class:`_LegContext`)."""
        fp = self.footprint(carrying)
        slot = self.slot(target)
        pl = self.path_planner(obstacles, carrying)
        goal = pl.approach_pose(slot, self.d_dock, fp)
        goals = [goal]
        if carrying and self.settings.legs.place_standoff > 0:  # a place: room to settle on the normal first
            d = self.settings.legs.place_standoff
            g2 = (goal[0] - d * math.cos(goal[2]), goal[1] - d * math.sin(goal[2]), goal[2])
            if pl.is_free(g2[:2], fp):
                goals = [g2, goal]
        lg = self.settings.legs
        final_straight = lg.place_straight if carrying else lg.pick_straight
        final_min_radius = lg.place_min_radius if carrying else lg.pick_min_radius

        def smoothed(path, aligned):
            return pl.smooth(path, fp, final_straight=final_straight if aligned else 0.0,
                             min_radius=lg.min_radius, final_min_radius=final_min_radius)

        return _LegContext(pl, fp, slot, goals, lg.join_inflate if carrying else 0.0,  # empty: the turning circle
                           final_straight, final_min_radius, smoothed)

    def _via_leg(self, ctx: "_LegContext", pose, leg: LegPlan, carrying: bool, dock: str,
                 seconds: float | None = None) -> tuple[LegPlan, float]:
        """``legs.via_grid``: the leg through one grid point (:mod:`.vias`) that the follower's kinematic run
        (:meth:`leg_time`) finds at least ``VIA_MIN_GAIN`` s faster than ``leg`` (``seconds``, if known), of the
        ``VIA_TIMED`` best estimated, with its seconds; else ``leg`` and its seconds."""
        t_leg = seconds if seconds is not None else self.leg_time(leg, pose, carrying)
        beat = t_leg - VIA_MIN_GAIN
        found = via_candidates(ctx.planner, ctx.footprint, self.carry_limits if carrying else self.limits, self.dt,
                               pose, ctx.goals, step=self.settings.legs.via_grid, join=ctx.join, beat=beat,
                               end_speed=self.entry_speed(dock), tail=lambda g: self._dock_tail(g, leg.slot, carrying),
                               smoothed=lambda path: ctx.smoothed(path, True), final_straight=ctx.final_straight,
                               final_min_radius=ctx.final_min_radius)
        best = (leg, t_leg)
        for c in found[:VIA_TIMED]:
            cand = LegPlan(c.path, c.smooth, c.goal, True, self.entry_speed(dock), leg.slot)
            t = self.leg_time(cand, pose, carrying, limit=beat - self._dock_tail(c.goal, leg.slot, carrying))
            if t < beat:
                beat, best = t, (cand, t)
        return best

    @staticmethod
    def _arc_join_leg(pl, pose, goals, fp, join: float, arc_join: float, smoothed):
        """``legs.arc_join``: the leg joining the normal of the first of ``goals`` that allows it at the point
        nearest the slot (``ARC_JOIN_DISTANCES``) whose corner the smoothed path rounds into an arc, as
        ``(path, goal, smoothed path)``; None if there is none (the leg stays as planned without it)."""
        for g in goals:
            found = pl.plan(tuple(pose[:2]), g[:2], fp)  # (one search for every point tried)
            for d in ARC_JOIN_DISTANCES:
                path, aligned = pl.plan_to_pose(tuple(pose[:2]), g, fp, distances=(d,), join_inflate=join,
                                                arc_join=arc_join, path=found)
                if aligned:
                    sp = smoothed(path, True)
                    if pl.corner_rounded(path, sp):  # (else it would turn where its circle is not clear)
                        return path, g, sp
        return None

    def plan_on_arcs(self, obstacles: FieldObstacles, pose, target: SlotRef) -> LegPlan:
        """The leg to a place on arcs only (:mod:`.hybrid`; carrying): to a point on the slot's normal, then
        straight to the approach pose and on into the place at the place's entry speed. Raises NoPath when the
        slot has no approach pose, NoCarryPath (saying why) when no such path is found (the caller plans the
        usual leg, with turns on the spot)."""
        fp = self.fp_carry
        slot = self.field.slot(target.zone, target.number)
        pl = self.path_planner(obstacles, carrying=True)
        goal = pl.approach_pose(slot, self.d_dock, fp)
        cp = CarryPlanner(pl.obstacles, fp, radius=self.settings.carry.radius, max_expansions=5000,
                          inflate=self.settings.carry.inflate)
        bx, by = -math.cos(goal[2]), -math.sin(goal[2])
        sp = None
        err = NoCarryPath("no straight line along the normal is clear")
        for d in (0.12, 0.06, 0.0):  # a straight line along the normal before the approach pose, if it can
            aim = (goal[0] + d * bx, goal[1] + d * by, goal[2]) if d > 0 else goal
            if d > 0 and not all(cp.free(goal[0] + u * d * bx, goal[1] + u * d * by, goal[2])
                                 for u in np.linspace(0, 1, 6)):
                continue
            try:
                sp = cp.plan(tuple(pose), aim)
                break
            except NoCarryPath as e:
                err = e
        if sp is None:
            raise err
        if d == 0.0:
            aim = goal
        if aim is not goal:  # the straight line on to the approach pose: forwards, along the normal
            last = sp.pieces[-1]
            n = max(2, int(math.hypot(goal[0] - aim[0], goal[1] - aim[1]) / 0.01) + 1)
            line = np.linspace(last.xy[-1], goal[:2], n)
            h = math.atan2(goal[1] - line[0][1], goal[0] - line[0][0])
            if last.reverse:  # the search ended backing up: a stop, then a forward piece
                ss = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(line, axis=0).T))])
                sp = SmoothPath(sp.pieces + (Piece(line, ss, np.full(n, h), np.zeros(n)),))
            else:
                xy = np.concatenate([last.xy, line[1:]])
                ss = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
                psi = np.concatenate([last.psi, np.full(n - 1, h)])
                piece = Piece(xy, ss, psi, np.concatenate([last.kappa, np.zeros(n - 1)]))
                sp = SmoothPath(sp.pieces[:-1] + (piece,))
        path = Path(tuple((float(x), float(y)) for x, y in sp.points[::5]) + (tuple(map(float, goal[:2])),),
                    fp.radius)
        return LegPlan(path, sp, goal, True, self.entry_speed("place"), slot)

    def leg_time(self, leg: LegPlan, pose, carrying: bool, limit: float = 40.0) -> float:
        """Seconds the leg ``leg`` would take from ``pose`` (a kinematic run of the follower with the limits
        it would drive with, the robot starting at rest), plus the docking approach from its end to the dock
        or place pose at the docking speed."""
        f = PathFollower(self.carry_limits if carrying else self.limits, self.dt)
        if self.settings.legs.smooth:
            f.start(leg.smooth, final_heading=None if leg.end_speed > 0 else leg.goal[2], end_speed=leg.end_speed)
        else:
            f.start(leg.smooth, final_heading=leg.goal[2])
        x, y, th = (float(v) for v in pose[:3])
        t, dt = 0.0, self.dt
        while t < limit:
            o = f.step((x, y, th))
            if o.done:
                break
            x += o.v * math.cos(th) * dt
            y += o.v * math.sin(th) * dt
            th += o.w * dt
            t += dt
        return t + self._dock_tail(leg.goal, leg.slot, carrying)

    def _dock_tail(self, goal, slot, carrying: bool) -> float:
        """s of the docking approach from the approach pose ``goal`` to ``slot``'s dock or place pose."""
        d_end = math.hypot(goal[0] - slot.xy[0], goal[1] - slot.xy[1]) - self.d_dock
        return max(d_end, 0.0) / self.entry_speed("place" if carrying else "pick")

    # ------------------------------------------------------------------------------------------ around a leg
    def escape_point(self, obstacles: FieldObstacles, pose, carrying: bool) -> Escape | None:
        """Where a robot too close to something to plan from (``pose``) drives first, or None. Carrying, the
        nearest clear point straight ahead or behind if there is one within 0.3 m (the escape drive does not turn
        on the spot with a part, and a point beside the robot it could not reach: whole stack, round 3, three
        escapes barely moved it and it stood still for 170 s); else the nearest clear point."""
        pl = self.path_planner(obstacles, carrying)
        fp = self.footprint(carrying)
        if carrying:
            p = pl.escape_straight(pose, fp)
            if p is not None:
                return Escape(p, straight=True)
        try:
            p = pl.escape_point(tuple(pose[:2]), fp)
        except NoPath:
            return None
        return None if p is None else Escape(p, straight=False)

    def retreat(self, obstacles: FieldObstacles, target: SlotRef, carrying: bool) -> float:
        """Distance from ``target``'s centre to back out to after docking there (m): the approach distance of
        the footprint the robot will have afterwards (``carrying``), at least :data:`MACHINE_CLEARANCE` from a
        machine input. ``obstacles``: without the part in ``target`` (the one being picked or placed);
        ``target``: a SlotRef or a slot itself (:meth:`slot`)."""
        slot = self.slot(target)
        fp = self.footprint(carrying)
        pl = self.path_planner(obstacles, carrying)
        try:
            x, y, _ = pl.approach_pose(slot, self.d_dock, fp)
            d = math.hypot(x - slot.xy[0], y - slot.xy[1])
        except NoPath:  # (a remembered blocked spot in front of the slot): the turning circle's distance
            d = self.d_dock + fp.radius - fp.front + 0.02
        if slot.role == "input":  # a machine starts only once base_link is 0.17 m from its input
            d = max(d, MACHINE_CLEARANCE)
        return d
