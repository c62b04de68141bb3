"""The experiment's routes (reference and second), the pure-pursuit controller and the error metrics (pure, no ROS)."""
import math

import numpy as np
import pytest

from robotatfactory.localization.frames import clearance, random_poses
from robotatfactory.localization.geometry import compose2
from robotatfactory.localization.metrics import errors, interpolate, odometry_in_map, stats
from robotatfactory.localization.route import EIGHT, LOOP, PurePursuit, densify, length, make_route, route


def test_route_keeps_clear_of_walls_and_parts(field):
    pts = densify(route(1), 0.005)
    assert min(clearance(field, x, y) for x, y in pts) > 0.12
    slots = np.array([s.xy for s in field.slots])
    assert min(np.min(np.hypot(*(slots - p).T)) for p in pts) > 0.15
    a = field.floor
    assert np.all((pts[:, 0] > a.x[0] + 0.09) & (pts[:, 0] < a.x[1] - 0.09))
    assert np.all((pts[:, 1] > a.y[0] + 0.09) & (pts[:, 1] < a.y[1] - 0.09))
    # it visits the whole field: all four quadrants, both sides of both machines
    assert pts[:, 0].min() < -0.65 and pts[:, 0].max() > 0.65 and pts[:, 1].min() < -0.35 and pts[:, 1].max() > 0.35
    assert field.start_area.contains(*LOOP[0])
    assert 1.95 * length(route(1)) < length(route(2)) < 2 * length(route(1))
    assert np.array_equal(route(2), make_route("reference", 2).points)
    assert 1.95 * length(route(1, "second")) < length(route(2, "second")) < 2 * length(route(1, "second"))


def _drive(pp, pose, t_max=200.0, dt=0.04):
    t, traj, cmds = 0.0, [], []
    while not pp.done and t < t_max:
        v, w = pp.command(pose)
        cmds.append((v, w))
        pose = compose2(pose, (v * dt * math.cos(w * dt / 2), v * dt * math.sin(w * dt / 2), w * dt))
        t += dt
        traj.append(pose)
    return t, np.array(traj), np.array(cmds)


@pytest.mark.parametrize("field_name", ["rules2026", "simtwo2022"])
def test_second_route_is_clear_different_and_drivable(field_name):
    from robotatfactory.field import load_field

    field = load_field(field_name)
    r = make_route("second", 1)
    assert r.name == "second" and len(r.points) == len(EIGHT) and r.stops.sum() == 4
    pts = densify(r.points, 0.005)
    slots = np.array([s.xy for s in field.slots])
    assert min(clearance(field, x, y) for x, y in pts) > 0.12
    assert min(np.min(np.hypot(*(slots - p).T)) for p in pts) > 0.15
    a = field.floor
    assert np.all((pts[:, 0] > a.x[0] + 0.08) & (pts[:, 0] < a.x[1] - 0.08))
    assert np.all((pts[:, 1] > a.y[0] + 0.08) & (pts[:, 1] < a.y[1] - 0.08))
    assert field.start_area.contains(*r.points[0]) and field.start_area.contains(*r.points[-1])
    # a figure-eight: it crosses the corridor between the machines diagonally, twice
    near = np.flatnonzero(np.hypot(pts[:, 0], pts[:, 1] + 0.03) < 0.06)
    assert len(near) and np.ptp(near) > len(pts) // 4  # two passes through the middle, far apart in time
    steps = np.diff(pts[near], axis=0)
    slopes = steps[:, 1] / np.where(np.abs(steps[:, 0]) > 1e-9, steps[:, 0], np.nan)
    assert np.nanmin(slopes) < -0.5 and np.nanmax(slopes) > 0.5  # crossing diagonals
    # different poses from the reference loop: at most of its points, no point of the loop within 10 cm is
    # driven within 45 degrees of the same heading (the field is small: positions overlap, headings do not)
    ref = densify(route(1), 0.005)

    def headings(q):
        d = np.diff(q, axis=0)
        return np.arctan2(d[:, 1], d[:, 0])

    h2, hr = headings(pts), headings(ref)
    new = [not np.any((np.hypot(*(ref[1:] - p).T) < 0.10) & (np.abs(np.angle(np.exp(1j * (hr - h)))) < np.pi / 4))
           for p, h in zip(pts[1:], h2)]
    assert np.mean(new) > 0.5
    # driven: it stays clear, runs at 0.12..0.25 m/s with the 0.2 m/s cruise, reaches each visit and turns
    # on the spot there, and circles machine B anticlockwise (the reference loop runs clockwise)
    pp = PurePursuit.for_route(r, speed=0.2)
    t, traj, cmds = _drive(pp, r.start)
    assert pp.done and 40 < t < 100
    assert min(clearance(field, x, y) for x, y, _ in traj) > 0.12
    moving = cmds[cmds[:, 0] > 0.1, 0]
    assert moving.max() == pytest.approx(0.25, abs=0.002) and np.percentile(moving, 5) < 0.15
    assert np.sum((cmds[:, 0] == 0) & (cmds[:, 1] != 0)) > 10  # turns on the spot
    for k in np.flatnonzero(r.stops):
        assert np.min(np.hypot(*(traj[:, :2] - r.points[k]).T)) < 0.025
    east = traj[traj[:, 0] > 0.55]  # the east side of machine B: driven north (anticlockwise)
    assert np.median(np.sin(east[:, 2])) > 0.5
    with pytest.raises(ValueError):
        make_route("third", 1)


def test_pure_pursuit_drives_the_route(field):
    pp = PurePursuit(route(1), speed=0.2)
    pose, t, dt = (LOOP[0][0], LOOP[0][1], math.pi / 2), 0.0, 0.04
    dev = []
    path = densify(route(1), 0.005)
    while not pp.done and t < 120:
        v, w = pp.command(pose)
        assert 0 <= v <= 0.2 + 1e-9 and abs(w) <= 3.0
        pose = compose2(pose, (v * dt * math.cos(w * dt / 2), v * dt * math.sin(w * dt / 2), w * dt))
        t += dt
        dev.append(np.min(np.hypot(*(path - pose[:2]).T)))
    assert pp.done and pp.progress == pytest.approx(1.0, abs=0.01)
    assert 25 < t < 60
    assert max(dev) < 0.03  # never more than 3 cm off the polyline (corners are cut a little)


def test_metrics_on_known_answers():
    t = np.linspace(0, 10, 101)
    gt = np.column_stack([0.1 * t, np.zeros_like(t), np.full_like(t, 3.1)])
    gt[50:, 2] = -3.1  # the heading crosses +-pi
    q = interpolate(np.array([-1.0, 2.05, 4.95, 11.0]), t, gt)
    assert np.isnan(q[0]).all() and np.isnan(q[3]).all()
    assert q[1] == pytest.approx([0.205, 0.0, 3.1])
    assert abs(abs(q[2, 2]) - math.pi) < 0.0301  # interpolated across the wrap, not through zero
    est = gt.copy()
    est[:, 1] += 0.003
    est[:, 2] += 0.01
    te, ep, eh = errors(t, est, t, gt)
    assert len(te) == 101 and ep == pytest.approx(np.full(101, 0.003)) and eh == pytest.approx(np.full(101, 0.01))
    s = stats(np.array([3.0, 4.0]))
    assert s["rmse"] == pytest.approx(math.sqrt(12.5)) and s["max"] == 4.0 and s["n"] == 2
    assert stats(np.array([]))["n"] == 0
    # odometry from its own origin placed at the true start
    odo = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])
    m = odometry_in_map(odo, (2.0, 3.0, math.pi / 2))
    assert m[0] == pytest.approx([2.0, 3.0, math.pi / 2])
    assert m[1] == pytest.approx([2.0, 4.0, math.pi / 2])
    assert m[2][:2] == pytest.approx([1.0, 4.0]) and abs(abs(m[2][2]) - math.pi) < 1e-9


def test_random_poses_are_clear(field):
    for x, y, th in random_poses(field, 50, seed=3):
        assert clearance(field, x, y) >= 0.08 and -math.pi <= th <= math.pi


def test_calibration_drive_is_clear_and_turns_at_its_visits(field):
    r = make_route("calibration", 1)
    assert r.stops.sum() == 3 and field.start_area.contains(*r.points[0])
    pts = densify(r.points, 0.005)
    assert min(clearance(field, x, y) for x, y in pts) > 0.12
    slots = np.array([s.xy for s in field.slots])
    assert min(np.min(np.hypot(*(slots - p).T)) for p in pts) > 0.15
    pp = PurePursuit.for_route(r, speed=0.15)
    t, traj, cmds = _drive(pp, r.start)
    assert pp.done and 20 < t < 60
    for k in np.flatnonzero(r.stops):
        assert np.min(np.hypot(*(traj[:, :2] - r.points[k]).T)) < 0.025
