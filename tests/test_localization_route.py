"""The experiment's reference route, its pure-pursuit controller and the error metrics (pure, no ROS)."""
import math

import numpy as np
import pytest

from robotatfactory.localization.frames import clearance, random_poses
from robotatfactory.localization.geometry import compose2
from robotatfactory.localization.metrics import errors, interpolate, odometry_in_map, stats
from robotatfactory.localization.route import LOOP, PurePursuit, densify, length, route


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
