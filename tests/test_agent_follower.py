"""The path follower: its rules on a kinematic robot, and in closed loop on the bare stand-in simulator
(SimTwo's speed PID, no ramp). The simulator's ground-truth pose stands in for the EKF only here."""
import math
from dataclasses import replace

import numpy as np
import pytest

from robotatfactory.agent.follower import DriveLimits, PathFollower
from robotatfactory.agent.footprint import dock_distance, robot_footprint, wrap
from robotatfactory.agent.obstacles import FieldObstacles
from robotatfactory.agent.planner import PathPlanner
from robotatfactory.sim import SimConfig
from robotatfactory.simtwo import Command


def polyline_distance(p, pts):
    pts = np.asarray(pts)
    best = math.inf
    for a, b in zip(pts[:-1], pts[1:]):
        d = b - a
        u = np.clip(np.dot(p - a, d) / max(np.dot(d, d), 1e-12), 0.0, 1.0)
        best = min(best, float(np.hypot(*(p - a - u * d))))
    return best


def drive_kinematic(f: PathFollower, pose, dt: float, steps: int = 1000):
    """Run the follower on an ideal unicycle from ``pose`` until done: (outputs, poses after each step)."""
    x, y, th = pose
    outs, poses = [], []
    for _ in range(steps):
        o = f.step((x, y, th))
        outs.append(o)
        x += o.v * math.cos(th) * dt
        y += o.v * math.sin(th) * dt
        th = wrap(th + o.w * dt)
        poses.append((x, y, th))
        if o.done:
            break
    return outs, poses


def test_rules_on_a_kinematic_robot(robot):
    lim = DriveLimits.from_robot(robot)
    assert lim.v_max == pytest.approx(0.4) and lim.alpha_max == pytest.approx(lim.a_max / (robot.track / 2))
    dt = robot.control_period
    f = PathFollower(lim, dt)
    f.start([(0.0, 0.0), (0.6, 0.0), (0.6, 0.3)], final_heading=math.pi / 2)
    outs, poses = drive_kinematic(f, (0.0, 0.0, math.pi), dt)  # facing away from the path
    x, y, th = poses[-1]
    assert outs[-1].done and math.hypot(x - 0.6, y - 0.3) < 0.01 and abs(wrap(th - math.pi / 2)) < 0.02
    v = np.array([o.v for o in outs])
    w = np.array([o.w for o in outs])
    assert np.all(np.abs(np.diff(v)) <= lim.a_max * dt + 1e-12)
    assert np.all(np.abs(np.diff(w)) <= lim.alpha_max * dt + 1e-12)
    assert v.max() <= lim.v_max + 1e-12 and np.abs(w).max() <= lim.w_max + 1e-12
    # no translation while the heading error is large: the first cycles only turn
    assert all(o.v == 0.0 for o in outs if abs(o.heading_error) > lim.heading_tolerance)
    assert all(o.v == 0.0 for o in outs if o.phase == "turn" and o.w != 0.0)
    assert sum(o.phase == "turn" and o.w != 0.0 for o in outs) > 10  # it did turn in place (start, corner)
    assert outs[0].v == 0.0 and outs[0].w > 0
    # slow in the last 0.2 m, stops at the corner (a 90 degree turn)
    assert all(o.v <= lim.v_final + 1e-9 for o in outs if o.remaining < lim.slow_distance and o.phase == "drive")
    assert v.max() > 0.3  # but it does speed up on the long leg


def test_a_stop_at_a_corner_is_reached_not_crept_towards(robot):
    """On a pose that follows the commands exactly (as leg_time's kinematic run), the speed profile only tends
    to 0 at a corner's stop: the follower used to creep the last 5 mm for 3.6 s (90 cycles) before the turn,
    and leg_time counted those seconds in every leg with a stop. The turn now begins within a few cycles."""
    lim = DriveLimits.from_robot(robot)
    dt = robot.control_period
    f = PathFollower(lim, dt)
    f.start([(0.0, 0.0), (0.6, 0.0), (0.6, 0.3)], final_heading=math.pi / 2)
    outs, poses = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
    near = next(k for k, p in enumerate(poses) if abs(p[0] - 0.6) < lim.position_tolerance)
    turn = next(k for k, o in enumerate(outs) if k > near and o.v == 0.0 and o.w != 0.0)
    assert turn - near <= 10
    assert abs(poses[turn][0] - 0.6) < lim.position_tolerance and outs[-1].done


@pytest.fixture(scope="module")
def sim(field, robot):
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False))
    yield s
    s.close()


def test_closed_loop_on_the_simulator(sim, field, robot):
    """From the start area to two approach poses and back out in reverse: on the path within 1 cm, at the
    goal within 5 mm and 0.03 rad, never touching a wall (exact outline on the true pose)."""
    fp = robot_footprint(robot)
    ob = FieldObstacles(field, [])
    pl = PathPlanner(ob)
    lim = DriveLimits.from_robot(robot)
    fol = PathFollower(lim, robot.control_period)
    for zone, n in (("machine_B", 1), ("machine_A", 3)):
        slot = field.slot(zone, n)
        goal = pl.approach_pose(slot, dock_distance(robot, field.part), fp)
        path = pl.plan(sim.pose[:2], goal[:2], fp)
        fol.start(path.points, final_heading=goal[2])
        t0, worst = sim.time, 0.0
        budget = path.length / lim.v_max + 2 * math.pi / lim.w_max * len(path.points) + 3.0
        for _ in range(int(budget / robot.control_period)):
            o = fol.step(sim.pose)
            sim.step_cycle(Command(o.v, o.w, False))
            worst = max(worst, polyline_distance(np.array(sim.pose[:2]), path.points))
            assert not ob.collides(fp, sim.pose), sim.pose
            if o.done:
                break
        x, y, th = sim.pose
        assert o.done, f"not there within {budget:.1f} s"
        assert math.hypot(x - goal[0], y - goal[1]) < 0.005 and abs(wrap(th - goal[2])) < 0.03
        assert worst < 0.01
        print(f"{slot.name}: {path.length:.2f} m in {sim.time - t0:.2f} s, off the path <= {worst * 1000:.1f} mm")
        # back out 12 cm, the back first
        back = (x - 0.12 * math.cos(th), y - 0.12 * math.sin(th))
        fol.start([(x, y), back], reverse=True)
        for _ in range(200):
            o = fol.step(sim.pose)
            assert o.v <= 0.0
            sim.step_cycle(Command(o.v, o.w, False))
            if o.done:
                break
        assert o.done and math.hypot(sim.pose[0] - back[0], sim.pose[1] - back[1]) < 0.005
        assert abs(wrap(sim.pose[2] - th)) < 0.03


def test_extrapolation_is_exact_on_arcs():
    from robotatfactory.agent.predict import extrapolate

    # a quarter circle of radius 0.5 m, left turn, from the origin heading +x
    x, y, th = extrapolate((0.0, 0.0, 0.0), 0.5 * math.pi / 2, math.pi / 2, 1.0)
    assert (x, y, th) == pytest.approx((0.5, 0.5, math.pi / 2), abs=1e-12)
    assert extrapolate((1.0, 2.0, math.pi), 0.2, 0.0, 0.5) == pytest.approx((0.9, 2.0, math.pi))
    assert extrapolate((1.0, 2.0, 3.0), 0.2, 1.0, 0.0) == (1.0, 2.0, 3.0)
    # the turn in place: heading only, wrapped
    assert extrapolate((0.0, 0.0, 3.0), 0.0, 2.0, 0.1) == pytest.approx((0.0, 0.0, 3.2 - 2 * math.pi))


def test_a_rounded_corner_is_driven_through_without_stopping(robot):
    """A 90 degree corner rounded with a 0.2 m arc: the robot turns while it drives (the speed stays up, the
    turn rate follows the arc), within the wheels' speed limit, and stays within a few mm of the path."""
    from robotatfactory.agent.smooth import smooth_path

    lim = DriveLimits.from_robot(robot)
    dt = robot.control_period
    sp = smooth_path([(0.0, 0.0), (0.8, 0.0), (0.8, 0.8)], arc_clear=lambda xy, psi: True, radii=(0.2,))
    assert len(sp.pieces) == 1  # no stop: the corner is an arc
    f = PathFollower(lim, dt)
    f.start(sp)
    outs, poses = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
    x, y, th = poses[-1]
    worst = max(float(np.min(np.hypot(sp.points[:, 0] - px, sp.points[:, 1] - py))) for px, py, _ in poses)
    assert outs[-1].done and math.hypot(x - 0.8, y - 0.8) < 0.01
    on_arc = [o for o in outs if 0.75 * math.pi / 2 > abs(wrap(o.heading_error)) and 0.3 < o.remaining < 0.9]
    v = np.array([o.v for o in outs])
    w = np.array([o.w for o in outs])
    assert v[(v > 0)].size and min(o.v for o in on_arc) > 0.15  # no stop at the corner
    assert np.all(v + np.abs(w) * lim.half_track <= lim.v_wheel + 1e-9)
    assert np.all(np.abs(np.diff(v)) <= lim.a_max * dt + 1e-12)
    assert np.all(np.abs(np.diff(w)) <= lim.alpha_max * dt + 1e-12)
    assert w.max() > 1.0  # it did turn while driving
    assert worst < 0.01


def test_far_off_the_path_the_follower_stops_and_says_so(robot):
    lim = DriveLimits.from_robot(robot)
    f = PathFollower(lim, robot.control_period)
    f.start([(0.0, 0.0), (1.0, 0.0)])
    o = f.step((0.3, 0.5, 0.0))  # half a metre beside it (pushed, or a pose jump)
    assert o.off_path > lim.max_off_path and not o.done and f.phase == "done"


def test_a_long_turn_on_the_spot_runs_at_the_long_spin_rate(robot):
    """DriveLimits.long_spin: a turn on the spot of more than long_spin rad runs at most w_long_spin throughout
    (carrying: the part slides less); a shorter one at the normal rate; both end on the heading."""
    dt = robot.control_period
    lim = DriveLimits.from_robot(robot, w_max=1.5, alpha_max=6.0, long_spin=2.4, w_long_spin=1.1)
    peaks = {}
    for turn in (2.6, 1.6, -2.6):
        f = PathFollower(lim, dt)
        f.start([(0.0, 0.0)], final_heading=turn)
        outs, poses = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
        assert outs[-1].done and abs(wrap(poses[-1][2] - turn)) < 0.02
        peaks[turn] = max(abs(o.w) for o in outs)
    assert peaks[2.6] <= 1.1 + 1e-9 and peaks[-2.6] <= 1.1 + 1e-9
    assert peaks[1.6] > 1.4
    f = PathFollower(DriveLimits.from_robot(robot, w_max=1.5, alpha_max=6.0), dt)  # without it: the normal rate
    f.start([(0.0, 0.0)], final_heading=2.6)
    assert max(abs(o.w) for o in drive_kinematic(f, (0.0, 0.0, 0.0), dt)[0]) > 1.4


def test_with_spin_settle_a_turn_on_the_spot_stops_on_the_heading_before_driving_off(robot):
    """DriveLimits.spin_settle: the turn at a corner ends standing within spin_settle of the aim before the robot
    speeds up (carrying, driving off a turn with the heading feedback turning back slips the wheels under the part,
    docs/localization.md); without it the robot drives off while still turning (within heading_tolerance / 2)."""
    dt = robot.control_period
    base = DriveLimits.from_robot(robot, w_max=1.5, alpha_max=6.0)
    drive_off = {}
    for settle in (0.0, 0.03):
        f = PathFollower(replace(base, spin_settle=settle), dt)
        f.start([(0.0, 0.0), (0.0, 0.5)])  # a quarter turn left on the spot, then half a metre straight
        outs, poses = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
        assert outs[-1].done and math.hypot(poses[-1][0], poses[-1][1] - 0.5) < 0.01
        first = next(i for i, o in enumerate(outs) if o.v > 0)  # the first cycle that moves forward
        drive_off[settle] = (abs(outs[first].w), abs(wrap(poses[first - 1][2] - math.pi / 2)))
    w_on, err_on = drive_off[0.03]
    assert w_on <= 6.0 * dt + 1e-9 and err_on <= 0.03  # stopped on the heading
    w_off, err_off = drive_off[0.0]
    assert w_off > 0.5 and err_off > 0.03  # still turning fast, the heading not yet reached


def test_a_given_top_speed_is_taken_as_given(robot):
    """drive.v_max above the default wheel limit (45 % of the no-load top speed, 0.46 m/s) is driven on a straight:
    it was capped at 0.46 without a word."""
    default = DriveLimits.from_robot(robot)
    assert default.v_max == pytest.approx(0.4) and default.v_wheel == pytest.approx(0.46, abs=0.01)
    fast = DriveLimits.from_robot(robot, v_max=0.6)
    assert fast.v_max == pytest.approx(0.6) and fast.v_wheel == pytest.approx(0.6)
    assert DriveLimits.from_robot(robot, v_max=0.6, v_wheel=0.5).v_wheel == pytest.approx(0.5)
    dt = robot.control_period
    f = PathFollower(fast, dt)
    f.start([(0.0, 0.0), (1.2, 0.0)])
    outs, _ = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
    assert max(o.v for o in outs) == pytest.approx(0.6, abs=1e-6)


def test_the_estimate_of_a_paths_time_follows_the_kinematic_run(robot):
    """:meth:`PathFollower.estimate` (the turns on the spot and the speed profile, no step run) is within 12 % of
    the kinematic run's time on paths with stops, arcs and long turns, with the normal and the carrying limits,
    and orders paths half a second apart as the run does."""
    from robotatfactory.agent.smooth import smooth_path

    dt = robot.control_period
    base = DriveLimits.from_robot(robot)
    carry = replace(base, w_max=1.5, alpha_max=6.0, long_spin=2.4, w_long_spin=1.1)
    paths = [[(0.0, 0.0), (0.6, 0.0), (0.6, 0.3)], [(0.0, 0.0), (0.3, 0.4), (0.9, 0.4), (1.0, -0.2)],
             [(0.0, 0.0), (-0.5, 0.1)], [(0.0, 0.0), (0.2, 0.0), (0.2, 0.2), (0.0, 0.2), (0.0, 0.5)]]
    for lim in (base, carry):
        runs, ests = [], []
        for pts in paths:
            sp = smooth_path(pts, radii=(0.2, 0.1), max_deviation=0.05)
            f = PathFollower(lim, dt)
            f.start(sp)
            outs, _ = drive_kinematic(f, (0.0, 0.0, 0.0), dt)
            assert outs[-1].done
            runs.append(len(outs) * dt)
            ests.append(PathFollower(lim, dt).estimate(sp, 0.0))
        for r, e in zip(runs, ests):
            assert e == pytest.approx(r, rel=0.12), (runs, ests)
        for i in range(len(paths)):  # a difference of half a second or more comes out the same way
            for j in range(len(paths)):
                if runs[i] - runs[j] >= 0.5:
                    assert ests[i] > ests[j], (runs, ests)
