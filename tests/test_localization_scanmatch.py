"""LIDAR scan matching against the field's map (robotatfactory.localization.scanmatch) and its use by the EKF."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robotatfactory.bench.drive import cast, field_boxes
from robotatfactory.errors import ConfigError
from robotatfactory.field import load_field
from robotatfactory.localization.config import from_dict
from robotatfactory.localization.ekf import SCAN, Ekf
from robotatfactory.localization.scanmatch import FieldMap, OdomHistory, ScanLocalizer, ScanMatchConfig, deskew
from robotatfactory.robot import load_robot

N = 360
ANGLES = np.arange(N) * 2 * math.pi / N


@pytest.fixture(scope="module")
def world():
    fld, robot = load_field("simtwo2022"), load_robot()
    return fld, robot, ScanLocalizer(fld, robot), field_boxes(fld, robot.lidar.xyz[2])


def _scan(boxes, pose, rng, extra=()):
    """Ranges from the laser at ``pose`` (the LIDAR sits on base_link's origin) with the LIDAR's noise model;
    ``extra``: more boxes (cx, cy, hx, hy, cos, sin) the map does not have."""
    x, y, th = pose
    d = cast(list(boxes) + list(extra), np.full(N, x), np.full(N, y), np.cos(ANGLES + th), np.sin(ANGLES + th))
    with np.errstate(invalid="ignore", over="ignore"):
        r = d + rng.normal(0, 1, N) * 0.001524 * np.exp(1.3103 * np.minimum(d, 6.0))
    r[~np.isfinite(d)] = np.inf
    return r


def _free_poses(boxes, rng, n):
    out = []
    while len(out) < n:
        p = (rng.uniform(-0.75, 0.75), rng.uniform(-0.45, 0.45), rng.uniform(-math.pi, math.pi))
        d = cast(boxes, np.full(N, p[0]), np.full(N, p[1]), np.cos(ANGLES), np.sin(ANGLES))
        if d.min() > 0.12:
            out.append(p)
    return out


def test_matches_random_poses_to_a_millimetre_with_honest_covariance(world):
    fld, robot, sl, boxes = world
    rng = np.random.default_rng(1)
    errs, nees, fails = [], [], 0
    for pose in _free_poses(boxes, rng, 60):
        prior = (pose[0] + rng.normal(0, 0.015), pose[1] + rng.normal(0, 0.015), pose[2] + rng.normal(0, 0.03))
        _, pts = sl.returns(_scan(boxes, pose, rng), ANGLES)
        f = sl.map.match(pts, prior, sl.cfg, sigma=sl.sigma(pts))
        if not f.ok:
            fails += 1
            continue
        e = np.array([f.pose[0] - pose[0], f.pose[1] - pose[1], math.remainder(f.pose[2] - pose[2], 2 * math.pi)])
        errs.append(e)
        nees.append(float(e @ np.linalg.solve(f.cov, e)))
    e = np.abs(np.array(errs))
    assert fails <= 3, f"{fails} of 60 scans found no fix"
    assert np.percentile(np.hypot(e[:, 0], e[:, 1]), 95) < 0.003
    assert np.percentile(np.degrees(e[:, 2]), 95) < 0.3
    assert max(nees) < 16.3  # chi-square 3 dof, 99.9 %: no fix is more certain than it is right


def test_a_rib_is_not_matched_by_its_back_face(world):
    """Across a 2 cm rib both faces are at signed distance 0: a prior 1.5-2 cm off must not snap to the far face."""
    fld, robot, sl, boxes = world
    rng = np.random.default_rng(2)
    pose = (0.62, -0.35, -math.pi / 2)  # in front of the outgoing warehouse's ribs, facing them
    _, pts = sl.returns(_scan(boxes, pose, rng), ANGLES)
    for dx in (-0.02, -0.015, 0.015, 0.02):
        f = sl.map.match(pts, (pose[0] + dx, pose[1], pose[2]), sl.cfg, sigma=sl.sigma(pts))
        assert f.ok and abs(f.pose[0] - pose[0]) < 0.003, (dx, f)


def test_things_not_in_the_map_are_left_out(world):
    """Two parts standing near the robot (boxes the map does not have) do not pull the fix."""
    fld, robot, sl, boxes = world
    rng = np.random.default_rng(3)
    pose = (0.0, -0.3, 0.3)
    parts = [(0.15, -0.2, 0.03, 0.045, 1.0, 0.0), (-0.1, -0.45, 0.03, 0.045, 1.0, 0.0)]
    _, pts = sl.returns(_scan(boxes, pose, rng, parts), ANGLES)
    f = sl.map.match(pts, (pose[0] + 0.01, pose[1] - 0.01, pose[2] + 0.02), sl.cfg, sigma=sl.sigma(pts))
    assert f.ok and math.hypot(f.pose[0] - pose[0], f.pose[1] - pose[1]) < 0.003
    assert f.inliers < f.points  # the parts' returns were counted out


def test_a_sweep_with_too_little_on_the_map_says_which_way():
    """Fewer than min_points returns on mapped surfaces: ``too_few_on_map``; enough of them, but fewer than
    min_inlier_share of the sweep (most on things the map does not have): ``mostly_off_map``."""
    fld = load_field("simtwo2022")
    m = FieldMap(fld, 0.05)
    pose = (0.47, -0.2, -math.pi / 2)  # facing the outgoing warehouse's back wall (y = -0.57)
    c, s = math.cos(pose[2]), math.sin(pose[2])

    def body(xs, ys):
        dx, dy = np.asarray(xs) - pose[0], np.asarray(ys) - pose[1]
        return np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)

    wall = lambda k: body(np.linspace(0.25, 0.70, k), np.full(k, -0.57))  # noqa: E731
    off_x, off_y = np.linspace(0.1, 0.4, 60), np.full(60, -0.3)  # in the open: a row of things the map lacks
    assert np.all(np.abs(m.distance(np.stack([off_x, off_y], axis=1), pose[:2])[0]) > 0.1)
    prior = (pose[0] + 0.005, pose[1] + 0.003, pose[2] + 0.005)
    cases = {"mostly_off_map": np.vstack([wall(40), body(off_x, off_y)]),  # 40 on the wall of 100
             "too_few_on_map": np.vstack([wall(20), body(off_x[:15], off_y[:15])])}  # 20 of 35
    for reason, pts in cases.items():
        f = m.match(pts, prior, ScanMatchConfig(), sigma=np.full(len(pts), 0.003))
        assert not f.ok and f.reason == reason, (reason, f)
    assert m.match(wall(40), prior, ScanMatchConfig(), sigma=np.full(40, 0.003)).ok  # the wall alone: a fix


def test_returns_on_the_robot_and_a_held_part_are_ignored(world):
    fld, robot, sl, boxes = world
    r = np.full(N, 0.5)
    r[0] = 0.12  # straight ahead: on a held part (the magnet's face at 0.08 m, the part 0.06 m deep)
    r[90] = 0.05  # to the left: on the robot's wheel
    r[10] = np.nan
    idx, _ = sl.returns(r, ANGLES)
    assert 0 not in idx and 90 not in idx and 10 not in idx and 20 in idx


def test_deskew_puts_a_moving_sweep_back_together():
    """A robot driving 0.2 m/s and turning 1 rad/s past a wall: the raw sweep smears the wall by over 1 cm,
    the deskewed one puts every return on it."""
    rays_t = np.linspace(0.0, 0.2, 50)
    odo = np.stack([0.2 * rays_t, np.zeros_like(rays_t), 1.0 * rays_t], axis=1)
    wall_x = 0.5
    pts = []
    for (x, y, th) in odo:  # each ray hits the wall x = 0.5 at world y = 0.1
        dx, dy = wall_x - x, 0.1 - y
        c, s = math.cos(th), math.sin(th)
        pts.append((c * dx + s * dy, -s * dx + c * dy))
    pts = np.array(pts)
    ref = tuple(odo[25])
    out = deskew(pts, odo, ref, (0.0, 0.0, 0.0))
    c, s = math.cos(ref[2]), math.sin(ref[2])
    world_x = ref[0] + c * out[:, 0] - s * out[:, 1]
    assert np.max(np.abs(world_x - wall_x)) < 1e-9
    raw_x = ref[0] + c * pts[:, 0] - s * pts[:, 1]
    assert np.max(np.abs(raw_x - wall_x)) > 0.01


def test_odom_history_interpolates_and_refuses_times_before_it():
    h = OdomHistory(keep_s=1.0)
    for k in range(50):
        h.add(k * 0.04, (k * 0.01, 0.0, 0.0))
    p = h.at(np.array([1.0, 1.02]))
    assert p is not None and abs(p[0, 0] - 0.25) < 1e-9 and abs(p[1, 0] - 0.255) < 1e-9
    assert h.at(np.array([0.0])) is None  # older than the history kept


def test_a_scan_fix_corrects_the_filter_but_never_initialises_it():
    ekf = Ekf()
    R = np.diag([1e-6, 1e-6, 1e-6])
    r = ekf.pose_fix(0.0, (0.0, 0.0, 0.0), R, source=SCAN)
    assert not r.accepted and not ekf.initialised
    ekf.initialise(0.0, (0.0, 0.0, 0.0), np.diag([1e-4, 1e-4, 1e-3]))
    ekf.odometry_pose(0.0, (0.0, 0.0, 0.0))
    ekf.odometry_pose(0.04, (0.0, 0.0, 0.0))
    r = ekf.pose_fix(0.04, (0.005, 0.0, 0.01), R, source=SCAN)
    assert r.accepted and abs(ekf.pose()[0] - 0.005) < 0.001
    # far off: gated, and however many in a row, never re-initialising (a camera fix may)
    for k in range(10):
        ekf.odometry_pose(0.08 + 0.04 * k, (0.0, 0.0, 0.0))
        r = ekf.pose_fix(0.08 + 0.04 * k, (0.3, 0.0, 0.0), R, source=SCAN)
        assert not r.accepted
    assert abs(ekf.pose()[0]) < 0.01
    assert ekf.counts["scan_gated"] == 10 and ekf.counts["scan_accepted"] == 1


def test_a_wall_alone_constrains_only_what_it_can():
    """Returns on one long straight face: the fix is certain across it and in heading, uncertain along it."""
    fld = load_field("simtwo2022")
    m = FieldMap(fld, 0.05)
    pose = (0.47, -0.2, -math.pi / 2)  # facing the outgoing warehouse's back wall (y = -0.57)
    ys = np.full(80, -0.57)
    xs = np.linspace(0.25, 0.70, 80)
    c, s = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = xs - pose[0], ys - pose[1]
    pts = np.stack([c * dx + s * dy, -s * dx + c * dy], axis=1)
    cfg = ScanMatchConfig(min_points=20)
    f = m.match(pts, (pose[0] + 0.01, pose[1] + 0.005, pose[2] + 0.01), cfg, sigma=np.full(80, 0.003))
    assert f.ok
    sx, sy = math.sqrt(f.cov[0, 0]), math.sqrt(f.cov[1, 1])
    assert sy < 0.003 and sx > 0.1
    assert abs(f.pose[1] - pose[1]) < 0.002 and abs(f.pose[2] - pose[2]) < 0.002


def test_settings_are_checked():
    with pytest.raises(ConfigError, match="scan_match.outlier_m must be a number > 0"):
        from_dict({"scan_match": {"outlier_m": 0}})
    with pytest.raises(ConfigError, match="scan_match.nope"):
        from_dict({"scan_match": {"nope": 1}})
    assert from_dict({"scan_match": {"enabled": False}}).scan_match.enabled is False


def test_a_scan_waits_for_the_odometry_of_its_last_ray(world):
    """The scan can arrive before the odometry of the cycle that carried it: it is matched only once odometry
    reaches its last ray (a pose held from an earlier cycle would smear the sweep's end), then once."""
    fld, robot, _, boxes = world
    sl = ScanLocalizer(fld, robot)
    rng = np.random.default_rng(4)
    pose = (0.47, -0.3, -math.pi / 2)
    r = _scan(boxes, pose, rng)
    for k in range(3):  # at rest, odometry up to 0.08 s
        sl.add_odom(k * 0.04, (0.0, 0.0, 0.0))
    assert sl.add_scan(r, ANGLES, 0.0, 0.2 / N) is None
    assert sl.fix_pending(0.08, pose) is None  # the last usable ray after 0.15 s: not covered yet
    sl.add_odom(0.24, (0.0, 0.0, 0.0))
    f = sl.fix_pending(0.24, pose)
    assert f is not None and f.ok and abs(f.t - 0.1) < 0.002
    assert math.hypot(f.pose[0] - pose[0], f.pose[1] - pose[1]) < 0.003
    assert sl.fix_pending(0.24, pose) is None  # matched once
    assert sl.add_scan(np.full(N, np.inf), ANGLES, 0.2, 0.2 / N).reason == "too_few_returns"


HELD_POSE = (-0.662, -0.155, math.radians(3))  # before machine A's input 3 on simtwo2022
HELD_PRIOR = (HELD_POSE[0] + 0.004, HELD_POSE[1] - 0.003, HELD_POSE[2] + math.radians(1.5))


def _held_part_sweep(world, visible_to_deg: float, extra=()):
    """A sweep at :data:`HELD_POSE` with a part held (and the boxes ``extra`` the map does not have), the rays
    from ``visible_to_deg`` to 330 deg hidden as the robot's body hides them."""
    fld, robot, _, boxes = world
    pose = HELD_POSE
    c, s = math.cos(pose[2]), math.sin(pose[2])
    d = float(robot.electromagnet["x"]) + fld.part.depth / 2
    part = (pose[0] + d * c, pose[1] + d * s, fld.part.depth / 2, fld.part.width / 2, c, s)
    r = _scan(boxes, pose, np.random.default_rng(5), extra=[part, *extra])
    r[(ANGLES > math.radians(visible_to_deg)) & (ANGLES < math.radians(330))] = np.inf
    return r


def _fixes(world, r, **options):
    """The fix of sweep ``r`` from :data:`HELD_PRIOR`, the robot at rest, for each value of the one boolean
    ``ScanMatchConfig`` option given (``name=(False, True)``)."""
    fld, robot, _, _ = world
    (name, values), = options.items()
    out = {}
    for v in values:
        sl = ScanLocalizer(fld, robot, ScanMatchConfig(**{name: v}))
        sl.add_odom(0.0, (0.0, 0.0, 0.0))
        sl.add_odom(0.24, (0.0, 0.0, 0.0))
        out[v] = sl.add_scan(r, ANGLES, 0.0, 0.2 / N) or sl.fix_pending(0.24, HELD_PRIOR)
    return out


def _assert_every_ray_fix(world, f, r):
    """``f`` is right within 0.5 deg (1.5 deg off before), and its covariance is every ray's fit with
    ``rays_per_independent`` doubled (the same surfaces, twice the rays)."""
    fld, robot, _, _ = world
    assert f.ok and f.every_ray
    assert abs(math.remainder(f.pose[2] - HELD_POSE[2], 2 * math.pi)) < math.radians(0.5)
    assert math.hypot(f.pose[0] - HELD_POSE[0], f.pose[1] - HELD_POSE[1]) < 0.004
    sl = ScanLocalizer(fld, robot, ScanMatchConfig(stride=1, rays_per_independent=16.0))
    _, pts = sl.returns(r, ANGLES)
    ref = sl.map.match(pts, HELD_PRIOR, sl.cfg, sigma=sl.sigma(pts))
    np.testing.assert_allclose(f.cov, ref.cov, rtol=0.05)


def test_every_ray_where_the_strided_returns_are_too_few(world):
    """Before machine A's input 3 on simtwo2022 with a part held, the LIDAR sees one wall past the robot: 17 returns
    at stride 2 on the stand-in (its body hides the rest). Cast here with the part and a sector the body hides:
    stride 2 gives too few, and with ``dense_when_few`` every ray gives the fix, its covariance twice the strided
    fit's would be for the same returns (the same surfaces, twice the rays); off, nothing changes."""
    r = _held_part_sweep(world, 70)
    out = _fixes(world, r, dense_when_few=(False, True))
    assert not out[False].ok and out[False].reason == "too_few_returns" and out[False].points < 30
    assert out[True].points >= 30
    _assert_every_ray_fix(world, out[True], r)
    assert from_dict({"scan_match": {"dense_when_few": False}}).scan_match.dense_when_few is False


def test_every_ray_where_the_strided_fit_has_too_few_on_the_map(world):
    """Enough strided returns (35) but a box the map does not have takes 9 of them, and 26 on the map are fewer
    than ``min_points``: with ``dense_when_few_on_map`` the sweep is fitted again with every ray (40 of 69 on the
    map) and gives the fix, its covariance as ``dense_when_few``'s; off, the sweep gives none."""
    r = _held_part_sweep(world, 110, extra=[(-0.45, 0.1, 0.06, 0.06, 1.0, 0.0)])  # a box on the floor
    out = _fixes(world, r, dense_when_few_on_map=(False, True))
    f = out[False]
    assert not f.ok and f.reason == "too_few_on_map" and f.points >= 30 and f.inliers < 30 and not f.every_ray
    assert out[True].inliers >= 30
    _assert_every_ray_fix(world, out[True], r)
    assert from_dict({"scan_match": {"dense_when_few_on_map": False}}).scan_match.dense_when_few_on_map is False
