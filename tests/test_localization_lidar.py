"""LIDAR beacons: extraction from simulated scans and the EKF's range/bearing update."""
import math

import numpy as np
import pytest

from robotatfactory.localization import reasons
from robotatfactory.localization.ekf import Ekf, beacon_model
from robotatfactory.localization.geometry import compose2, wrap_angle
from robotatfactory.localization.lidar import BeaconConfig, extract_beacons, simulate_scan


def _walls(field):
    segs = []
    for b in field.boxes:
        fp = b.footprint()
        segs += [(tuple(fp[i]), tuple(fp[(i + 1) % 4])) for i in range(4)]
    return segs


def _expected(pose, beacons, laser_xy, max_range=3.0):
    c, s = math.cos(pose[2]), math.sin(pose[2])
    lx, ly = pose[0] + c * laser_xy[0] - s * laser_xy[1], pose[1] + s * laser_xy[0] + c * laser_xy[1]
    out = []
    for bx, by in beacons:
        r = math.hypot(bx - lx, by - ly)
        if r < max_range:
            out.append((r, wrap_angle(math.atan2(by - ly, bx - lx) - pose[2])))
    return out


@pytest.mark.parametrize("pose", [(0.0, -0.3, 0.3), (0.6, 0.0, 1.0), (-0.6, -0.3, 2.0), (0.5, 0.4, -1.0), (0.2, -0.2, 3.0)])
def test_beacons_are_found_where_they_are(field, robot, pose):
    """In a scan with the field's walls, the beacon candidates include the beacons in view, accurately; wall
    corners can look like cylinders too, and the EKF's association (gated, against the known beacon
    positions) takes only the real ones."""
    angles = robot.lidar.angles()
    laser = robot.lidar.xyz[:2]
    scan = simulate_scan(pose, field.beacons, field.beacon_diameter, angles, laser_xy=laser,
                         rng=np.random.default_rng(0), segments=_walls(field))
    found = extract_beacons(scan, angles, BeaconConfig(diameter_m=field.beacon_diameter))
    exp = _expected(pose, field.beacons, laser)
    real = []
    for b in found:
        d = min(exp, key=lambda e: abs(e[0] - b.range_m) + abs(wrap_angle(e[1] - b.bearing_rad)))
        if abs(d[0] - b.range_m) < 0.03 and abs(wrap_angle(d[1] - b.bearing_rad)) < math.radians(2):
            real.append(b)
            assert abs(d[0] - b.range_m) < 0.015 and abs(wrap_angle(d[1] - b.bearing_rad)) < math.radians(1.0)
            # the reported uncertainty is in the right range (not absurdly small or large)
            assert 1e-7 < b.var_range < 1e-3 and 1e-7 < b.var_bearing < 1e-3
    assert len(real) >= 1
    ekf = Ekf()
    ekf.initialise(0.0, pose, np.diag([0.003 ** 2, 0.003 ** 2, math.radians(0.5) ** 2]))
    r = ekf.beacons(0.0, [b.as_tuple() for b in found], np.array(field.beacons), laser_xy=laser)
    assert r.accepted and r.n_used == len(real)
    x = ekf.pose()
    assert math.hypot(x[0] - pose[0], x[1] - pose[1]) < 0.005


def test_noise_free_centre_is_exact():
    angles = np.radians(np.linspace(-180, 180, 721))
    scan = simulate_scan((0, 0, 0), [(1.0, 0.5)], 0.09, angles)
    (b,) = extract_beacons(scan, angles, BeaconConfig(min_points=3))
    assert b.range_m == pytest.approx(math.hypot(1.0, 0.5), abs=1e-6)
    assert b.bearing_rad == pytest.approx(math.atan2(0.5, 1.0), abs=1e-6)


def test_walls_and_wide_objects_are_not_beacons():
    angles = np.radians(np.linspace(-180, 180, 361))
    segs = [((-1, 0.5), (1, 0.5)), ((0.8, -0.2), (0.8, -0.05))]  # a long wall, a 15 cm object
    scan = simulate_scan((0, 0, 0), [], 0.09, angles, segments=segs)
    assert extract_beacons(scan, angles) == []
    # a beacon right in front of the wall is still seen
    scan = simulate_scan((0, 0, 0), [(0.3, 0.4)], 0.09, angles, segments=segs)
    assert len(extract_beacons(scan, angles, BeaconConfig(foreground_m=0.03))) == 1
    # garbage scans
    assert extract_beacons(np.full(361, np.nan), angles) == []
    assert extract_beacons(np.array([1.0, 2.0]), angles) == []


def test_beacon_jacobian_matches_finite_differences():
    x = np.array([0.2, -0.1, 0.7])
    z, H = beacon_model(x, (0.888, 0.538), laser_xy=(0.03, 0.01))
    h = 1e-7
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        z2, _ = beacon_model(x + d, (0.888, 0.538), laser_xy=(0.03, 0.01))
        num = np.array([z2[0] - z[0], wrap_angle(z2[1] - z[1])]) / h
        np.testing.assert_allclose(H[:, i], num, atol=1e-5)


def test_ekf_with_beacons_only_stays_localised(field, robot):
    """No camera: odometry with a wrong calibration drifts; the beacons (LIDAR at 5 Hz) hold the filter."""
    angles = robot.lidar.angles()
    laser = robot.lidar.xyz[:2]
    beacons = np.array(field.beacons)
    rng = np.random.default_rng(1)

    def drive(use_beacons):
        ekf = Ekf()
        pose = (0.0, -0.35, 0.0)  # a circle of 0.3 m radius round the middle of the field
        ekf.initialise(0.0, pose, np.diag([1e-4, 1e-4, 1e-4]))
        worst = 0.0
        for k in range(1, 1500):
            t = k * 0.04
            v, w = 0.15, 0.5 + 0.1 * math.sin(0.3 * t)
            dl, dr = (v - w * 0.0675) * 0.04, (v + w * 0.0675) * 0.04
            ds, dth = (dl + dr) / 2, (dr - dl) / 0.135
            pose = compose2(pose, (ds / dth * math.sin(dth), ds / dth * (1 - math.cos(dth)), dth))
            ekf.odometry_wheels(t, dl * 1.02, dr * 0.98)  # 2 % calibration error per wheel, opposite signs
            if use_beacons and k % 5 == 0:
                scan = simulate_scan(pose, field.beacons, field.beacon_diameter, angles, laser_xy=laser, rng=rng)
                obs = extract_beacons(scan, angles)
                ekf.beacons(t, [o.as_tuple() for o in obs], beacons, laser_xy=laser)
            worst = max(worst, math.hypot(ekf.pose()[0] - pose[0], ekf.pose()[1] - pose[1]))
        return ekf, worst

    _, worst_without = drive(False)
    ekf, worst_with = drive(True)
    assert worst_without > 0.1
    assert worst_with < 0.03
    assert ekf.counts["accepted"] > 250


def test_a_false_beacon_is_gated():
    ekf = Ekf()
    ekf.initialise(0.0, (0.0, 0.0, 0.0), np.diag([1e-4, 1e-4, 1e-4]))
    ekf.odometry_increment(0.04, (0.0, 0.0, 0.0))
    beacons = np.array([[0.888, 0.538]])
    r = ekf.beacons(0.04, [(0.5, 0.0, 1e-4, 1e-4)], beacons)  # something 0.5 m ahead: not a beacon
    assert not r.accepted and r.reason == reasons.GATED
    true = (math.hypot(0.888, 0.538), math.atan2(0.538, 0.888))
    r = ekf.beacons(0.04, [(true[0] + 0.002, true[1], 1e-4, 1e-4)], beacons)
    assert r.accepted and r.n_used == 1
