"""Differential-drive odometry from cumulative ticks (robotatfactory.localization.odometry): pure."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from robotatfactory.localization.odometry import DiffDriveOdometry, wrap_angle


@pytest.fixture
def odo(robot):
    return DiffDriveOdometry(robot)


def test_straight_line(robot, odo):
    odo.update(0, 0, 0.0)
    n = 360  # one wheel revolution
    s = odo.update(n, n, 1.0)
    d = 2 * math.pi * robot.wheel_radius
    assert (s.x, s.y, s.theta) == pytest.approx((d, 0.0, 0.0))
    assert s.v == pytest.approx(d) and s.w == pytest.approx(0.0)
    assert s.left_angle == pytest.approx(2 * math.pi) and s.right_rate == pytest.approx(2 * math.pi)
    x, y, th, v, w = s  # unpacks as the shared interface says
    assert x == s.x and w == s.w


def test_spin_in_place(robot, odo):
    odo.update(0, 0, 0.0)
    # a quarter turn: each wheel travels track * pi/4, over the track odometry turns with (the robot file's
    # measured odometry_track, 0.1322 m: SimTwo's robot turns about a shorter track than its wheels' spacing)
    assert odo.track == robot.odometry_track == pytest.approx(0.1322) and robot.track == 0.135
    ticks = round(robot.odometry_track * math.pi / 4 / odo.m_per_tick)
    s = odo.update(-ticks, ticks, 0.5)
    assert s.x == pytest.approx(0, abs=1e-12) and s.y == pytest.approx(0, abs=1e-12)
    assert s.theta == pytest.approx(ticks * 2 * odo.m_per_tick / robot.odometry_track)
    assert s.v == pytest.approx(0) and s.w == pytest.approx(s.theta / 0.5)


def test_arc_is_integrated_exactly(robot):
    # constant curvature: the pose after one big step equals the pose after many small steps
    a = DiffDriveOdometry(robot)
    b = DiffDriveOdometry(robot)
    a.update(0, 0, 0)
    b.update(0, 0, 0)
    for i in range(1, 201):
        a.update(3 * i, 5 * i, 0.04 * i)
    sb = b.update(600, 1000, 8.0)
    sa = a.state()
    assert (sa.x, sa.y, sa.theta) == pytest.approx((sb.x, sb.y, sb.theta), abs=1e-9)


def test_lost_datagrams_lose_no_ticks(robot):
    """Differencing totals: skipping frames (a lost datagram) gives the same final pose for a straight path,
    and the same heading for any path."""
    rng = np.random.default_rng(0)
    dl = rng.integers(5, 20, 300)
    dr = rng.integers(5, 20, 300)
    tl, tr = np.cumsum(dl), np.cumsum(dr)
    full, lossy = DiffDriveOdometry(robot), DiffDriveOdometry(robot)
    full.update(0, 0, 0)
    lossy.update(0, 0, 0)
    keep = rng.random(300) > 0.3
    keep[-1] = True
    for i in range(300):
        full.update(tl[i], tr[i], 0.04 * (i + 1))
        if keep[i]:
            lossy.update(tl[i], tr[i], 0.04 * (i + 1))
    assert lossy.theta == pytest.approx(full.theta, abs=1e-12)
    assert lossy.state().left_angle == pytest.approx(full.state().left_angle)
    # positions agree to the arc-approximation error of the merged steps (small)
    assert math.hypot(lossy.x - full.x, lossy.y - full.y) < 0.01 * full.distance


def test_first_update_is_the_baseline_unless_counting_from_zero(robot):
    odo = DiffDriveOdometry(robot)
    s = odo.update(1000, 1000, 40.0)  # joined a running stream
    assert (s.x, s.v) == (0.0, 0.0)
    odo.reset(baseline=(0, 0), t=0.0)  # a stream known to start at Seq 0: the first cycle's ticks count
    s = odo.update(10, 10, 0.04)
    assert s.x == pytest.approx(10 * odo.m_per_tick)
    assert s.v == pytest.approx(10 * odo.m_per_tick / 0.04)


def test_covariance_grows_with_distance_and_is_symmetric(robot, odo):
    odo.update(0, 0, 0)
    covs = []
    for i in range(1, 101):
        s = odo.update(10 * i, 12 * i, 0.04 * i)
        covs.append(s.pose_cov)
    for c in covs:
        assert np.allclose(c, c.T)
        assert np.all(np.linalg.eigvalsh(c) >= -1e-15)
    tr = [np.trace(c) for c in covs]
    assert all(b > a for a, b in zip(tr, tr[1:]))
    s = odo.state()
    assert s.twist_cov.shape == (2, 2) and s.twist_cov[0, 0] > 0 and s.twist_cov[1, 1] > 0


def test_no_motion_no_covariance_growth(robot, odo):
    odo.update(0, 0, 0)
    for i in range(1, 50):
        s = odo.update(0, 0, 0.04 * i)
    assert np.allclose(s.pose_cov, 0)


def test_initial_pose_and_wrap(robot):
    odo = DiffDriveOdometry(robot, x=1.0, y=2.0, theta=3.1)
    odo.update(0, 0, 0)
    ticks = round(0.2 * robot.odometry_track / 2 / odo.m_per_tick)
    s = odo.update(-ticks, ticks, 1.0)
    assert -math.pi < s.theta <= math.pi
    assert s.theta == pytest.approx(wrap_angle(3.1 + 2 * ticks * odo.m_per_tick / robot.odometry_track))


def test_bad_geometry_rejected(robot):
    with pytest.raises(ValueError):
        DiffDriveOdometry(robot, wheel_radius=0)
    with pytest.raises(ValueError):
        DiffDriveOdometry(robot, slip_var_per_m=-1)


@settings(max_examples=200, deadline=None)
@given(st.floats(-20, 20, allow_nan=False))
def test_wrap_angle(a):
    w = wrap_angle(a)
    assert -math.pi < w <= math.pi
    assert math.cos(w) == pytest.approx(math.cos(a), abs=1e-9) and math.sin(w) == pytest.approx(math.sin(a), abs=1e-9)
