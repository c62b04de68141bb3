"""Carrying paths of arcs (hybrid A*, agent/hybrid.py): forward arcs no tighter than the radius, straight
reversing only, the loaded outline clear all along, the goal reached exactly (a Dubins shot); and the
follower driving them without a turn on the spot."""
import math

import numpy as np
import pytest

from robotatfactory.agent.follower import DriveLimits, PathFollower
from robotatfactory.agent.footprint import carrying_footprint, dock_distance, wrap
from robotatfactory.agent.hybrid import CarryPlanner, NoCarryPath, _arc, covering_circles, dubins_words
from robotatfactory.agent.obstacles import FieldObstacles, PartObstacle
from robotatfactory.agent.planner import PathPlanner


def test_dubins_words_reach_the_goal():
    s, g = (0.0, 0.0, 0.0), (0.5, 0.3, math.pi / 2)
    words = dubins_words(s, g, 0.2)
    assert len(words) >= 2 and words[0][0] == min(w[0] for w in words)
    for length, segs in words:
        st = s
        for k, L in segs:
            assert L >= 0.0 and k in (0.0, 5.0, -5.0)
            st = _arc(st, 1, k, L)
        assert st[0] == pytest.approx(g[0], abs=1e-9) and st[1] == pytest.approx(g[1], abs=1e-9)
        assert abs(wrap(st[2] - g[2])) < 1e-9
        assert length == pytest.approx(sum(L for _, L in segs))


def test_covering_circles_hold_the_outline(robot, field):
    fp = carrying_footprint(robot, field.part)
    circles = covering_circles(fp, 4)
    rng = np.random.default_rng(0)
    for r in fp.rects:
        pts = np.column_stack([rng.uniform(r.x0, r.x1, 200), rng.uniform(r.y0, r.y1, 200)])
        for x, y in pts:
            assert any(math.hypot(x - cx, y) <= rad + 1e-12 for cx, rad in circles)


def test_a_carry_from_a_warehouse_slot_backs_out_straight_and_turns_only_on_forward_arcs(field, robot):
    fc = carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    src, dst = field.slot("incoming", 1), field.slot("outgoing", 1)
    others = [PartObstacle(*field.slot("incoming", n).xy, field.slot("incoming", n).facing) for n in (2, 3, 4)]
    ob = FieldObstacles(field, others)
    pl = PathPlanner(ob)
    start, goal = pl.approach_pose(src, d, fc), pl.approach_pose(dst, d, fc)
    cp = CarryPlanner(ob, fc, radius=0.2)
    sp = cp.plan(start, goal)
    assert sp.pieces[0].reverse  # it backs out first (the wall is ahead)
    end = sp.pieces[-1]
    assert not end.reverse and np.hypot(*(end.xy[-1] - goal[:2])) < 1e-6 and abs(wrap(end.psi[-1] - goal[2])) < 1e-6
    for p in sp.pieces:
        assert np.all(np.abs(p.kappa) <= 1 / 0.2 + 1e-9)
        if p.reverse:
            assert np.all(p.kappa == 0.0)  # backwards only straight
        heading = p.psi + (math.pi if p.reverse else 0.0)
        for (x, y), th in zip(p.xy[::3], heading[::3]):
            assert not ob.collides(fc, (float(x), float(y), float(th)))


def test_a_search_over_its_expansion_budget_is_reported(field, robot):
    fc = carrying_footprint(robot, field.part)
    ob = FieldObstacles(field, [])
    cp = CarryPlanner(ob, fc, radius=0.2, max_expansions=50)
    with pytest.raises(NoCarryPath):
        cp.plan((-0.7, -0.4, 0.0), (0.7, 0.35, math.pi), )


def test_a_goal_inside_a_wall_has_no_path(field, robot):
    fc = carrying_footprint(robot, field.part)
    ob = FieldObstacles(field, [])
    box = field.boxes[0]
    cp = CarryPlanner(ob, fc, radius=0.2)
    with pytest.raises(NoCarryPath):
        cp.plan((-0.7, -0.4, 0.0), (float(box.center[0]), float(box.center[1]), 0.0))


def test_the_follower_drives_a_carry_path_without_turning_on_the_spot(field, robot):
    """A kinematic robot on the planned pieces: the turn rate never exceeds what the speed allows
    (spin_curvature x v + spin_slack), it reverses where the path does and ends on the goal."""
    fc = carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    ob = FieldObstacles(field, [])
    pl = PathPlanner(ob)
    start, goal = pl.approach_pose(field.slot("incoming", 1), d, fc), pl.approach_pose(field.slot("machine_A", 1), d, fc)
    sp = CarryPlanner(ob, fc, radius=0.2).plan(start, goal)
    lim = DriveLimits.from_robot(robot)
    fol = PathFollower(lim, robot.control_period)
    fol.start(sp, no_spin=True)
    x, y, th = start
    dt = robot.control_period
    outs = []
    for _ in range(3000):
        o = fol.step((x, y, th))
        outs.append(o)
        assert abs(o.w) <= lim.spin_curvature * abs(o.v) + lim.spin_slack + lim.alpha_max * dt + 1e-9
        x += o.v * math.cos(th) * dt
        y += o.v * math.sin(th) * dt
        th = wrap(th + o.w * dt)
        if o.done:
            break
    assert outs[-1].done and math.hypot(x - goal[0], y - goal[1]) < 0.01 and abs(wrap(th - goal[2])) < 0.05
    assert any(o.v < -0.05 for o in outs) == any(p.reverse for p in sp.pieces)
