"""The stand-in simulator's LIDAR, contact switch and electromagnet against the field's geometry."""
import math

import numpy as np
import pytest

from robotatfactory.sim import PartPlacement, SimConfig
from robotatfactory.simtwo import Command


def make(field, robot, **kw):
    from robotatfactory.sim import Simulator

    kw.setdefault("camera", False)
    kw.setdefault("competition", False)
    return Simulator(field, robot, SimConfig(**kw))


def full_sweep(sim, cmd=None):
    """Run one LIDAR period (0.2 s = 5 cycles) so every ray is measured at the present pose."""
    frame = None
    for _ in range(5):
        frame = sim.step_cycle(cmd)
    return frame


def rays_hitting_plane(robot, pose, axis, value, span, lo_hi):
    """Analytic ranges of the rays that hit the plane ``axis = value`` within ``lo_hi`` on the other axis,
    keeping away from the span's ends by 1 cm. Returns {ray index: distance}."""
    x, y, th = pose
    lx, ly, _ = robot.lidar.xyz
    ox, oy = x + math.cos(th) * lx - math.sin(th) * ly, y + math.sin(th) * lx + math.cos(th) * ly
    out = {}
    for i, a in enumerate(robot.lidar.angles()):
        d = np.array([math.cos(th + a), math.sin(th + a)])
        o = np.array([ox, oy])
        k = 0 if axis == "x" else 1
        if abs(d[k]) < 1e-6:
            continue
        t = (value - o[k]) / d[k]
        if t <= 0:
            continue
        other = (o + t * d)[1 - k]
        if lo_hi[0] + 0.01 <= other <= lo_hi[1] - 0.01:
            out[i] = t
    return out


def test_lidar_ranges_match_analytic_distances_to_wall_faces(field, robot):
    sim = make(field, robot, lidar_noise=False)
    # facing machine A's input face (x = -0.3575) between its ribs (faces at y = -0.065 and 0.065)
    pose = (-0.62, 0.0, 0.0)
    sim.set_pose(*pose)
    f = full_sweep(sim)
    expect = rays_hitting_plane(robot, pose, "x", -0.3575, None, (-0.065, 0.065))
    assert len(expect) >= 20
    for i, d in expect.items():
        assert f.ranges[i] == pytest.approx(d, abs=1e-4), i
    # facing the incoming warehouse's back wall (y = 0.565) between ribs x = -0.62 and -0.47 (faces +-0.01)
    pose = (-0.545, 0.30, math.pi / 2 + 0.1)
    sim.set_pose(*pose)
    f = full_sweep(sim)
    expect = rays_hitting_plane(robot, pose, "y", 0.565, None, (-0.61, -0.48))
    assert len(expect) >= 15
    for i, d in expect.items():
        assert f.ranges[i] == pytest.approx(d, abs=1e-4), i
    # nothing within 6 m towards +x from the east edge: no return is -1
    sim.set_pose(0.70, 0.0, 0.0)
    f = full_sweep(sim)
    ahead = np.abs(robot.lidar.angles()) < math.radians(20)
    assert np.all(f.ranges[ahead] == -1.0)
    # the robot never sees itself: every return is beyond its own body
    assert np.all((f.ranges == -1) | (f.ranges > 0.09))
    sim.close()


def test_lidar_sees_beacons_and_parts(field, robot):
    bx, by = field.beacons[3]  # (0.888, -0.538)
    sim = make(field, robot, lidar_noise=False, beacons=True,
               extra_parts=(PartPlacement("R", 0.0, 0.25, 0.0),))
    pose = (0.6, -0.30, 0.0)  # clear line of sight past the outgoing warehouse's last rib
    sim.set_pose(*pose)
    f = full_sweep(sim)
    ang = math.atan2(by - pose[1], bx - pose[0])
    i = int(np.argmin(np.abs(robot.lidar.angles() - ang)))
    # the ray's own direction against the beacon's circle
    u = np.array([math.cos(robot.lidar.angles()[i]), math.sin(robot.lidar.angles()[i])])
    c = np.array([bx - pose[0], by - pose[1]])
    t_mid = float(c @ u)
    half_chord = math.sqrt((field.beacon_diameter / 2) ** 2 - (float(c @ c) - t_mid ** 2))
    assert f.ranges[i] == pytest.approx(t_mid - half_chord, abs=1e-4)
    # the part's back face (x = 0.0 - 0.03) seen from the free floor behind it
    pose = (-0.2, 0.25, 0.0)
    sim.set_pose(*pose)
    f = full_sweep(sim)
    i = int(np.argmin(np.abs(robot.lidar.angles())))
    assert f.ranges[i] == pytest.approx(-0.03 - pose[0], abs=1e-4)
    sim.close()


def test_lidar_noise_follows_simtwos_law(field, robot):
    sim = make(field, robot, lidar_noise=True, seed=11)
    pose = (-0.62, 0.0, 0.0)
    sim.set_pose(*pose)
    i = int(np.argmin(np.abs(robot.lidar.angles())))
    true = -0.3575 - pose[0]
    samples = []
    for _ in range(120):  # 24 sweeps
        samples.append(full_sweep(sim).ranges[i])
    samples = np.array(samples)
    sigma = robot.lidar.noise_sigma(true)
    assert abs(samples.mean() - true) < 4 * sigma / math.sqrt(len(samples)) + 1e-4
    assert samples.std() == pytest.approx(sigma, rel=0.35)
    sim.close()


def test_lidar_rays_are_refreshed_in_turn_over_the_sweep(field, robot):
    """Ray i of a sweep is measured 0.2 s * i / 360 after the sweep starts: a 40 ms cycle refreshes the
    next 72 rays (counting on from the last cycle), one period refreshes them all."""
    sim = make(field, robot, lidar_noise=True, seed=5)
    sim.set_pose(-0.62, 0.0, 0.3)
    prev = full_sweep(sim).ranges
    returns = prev >= 0
    n = robot.lidar.rays
    per_cycle = round(n * robot.control_period / robot.lidar.period)  # 72
    changed_total = np.zeros(n, dtype=bool)
    for _ in range(5):
        f = sim.step_cycle(None)
        scheduled = np.zeros(n, dtype=bool)
        scheduled[np.arange(f.seq * per_cycle, (f.seq + 1) * per_cycle) % n] = True
        changed = f.ranges != prev
        # with noise on, a refreshed ray with a return always changes; nothing else does
        assert np.array_equal(changed, scheduled & returns)
        changed_total |= changed
        prev = f.ranges
    assert changed_total[returns].all() and returns.sum() > 100
    sim.close()


def test_contact_switch_presses_against_a_wall_only(field, robot):
    """The 1 cm beam at (0.08, -0.0165, 0.007) against the +x face (x = -0.16) of the incoming warehouse's
    last rib: heading -x, the beam meets the face at y = 0.54 when the robot is at y = 0.5565."""
    sim = make(field, robot, lidar=False)
    y = 0.54 + 0.0165
    sim.set_pose(-0.16 + 0.085, y, math.pi)  # beam tip 5 mm into the face
    assert sim.step_cycle(Command(0, 0, False)).contact
    sim.set_pose(-0.16 + 0.095, y, math.pi)  # 1.5 cm away: out of reach
    assert not sim.step_cycle(Command(0, 0, False)).contact
    sim.set_pose(0.15, y, math.pi)
    frames = [sim.step_cycle(Command(0.1, 0.0, False)) for _ in range(75)]
    assert not frames[0].contact and frames[-1].contact  # drove into the rib
    x, _, _ = sim.pose
    assert x == pytest.approx(-0.16 + 0.08, abs=0.003)  # stopped by the magnet's housing
    sim.close()


def test_electromagnet_picks_carries_and_releases_a_part(field, robot):
    part = PartPlacement("R", 0.0, -0.3, math.pi)  # plate towards -x, at x = -0.032
    sim = make(field, robot, lidar=False, start_pose=(-0.2, -0.3, 0.0), extra_parts=(part,))
    pid = sim.parts.ids[0]
    start = sim.part_pose(pid)
    # magnet on while approaching: nothing happens until the plate is within the 2 cm beam
    attached_at = None
    for k in range(40):
        f = sim.step_cycle(Command(0.1, 0.0, True))
        assert f.magnet
        if sim.held is not None:
            attached_at = sim.pose[0]
            break
    assert sim.held == pid
    assert -0.032 - 0.08 - 0.02 - 0.005 <= attached_at <= -0.032 - 0.08 + 0.001
    # carry it backwards through a turn: the part keeps its place in front of the magnet
    for _ in range(50):
        f = sim.step_cycle(Command(-0.15, 1.0, True))
    x, y, th = sim.pose
    px, py, pth = sim.part_pose(pid)
    rel = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]]) @ np.array([px - x, py - y])
    assert abs(th) > 1.0  # it turned
    assert rel[0] == pytest.approx(0.08 + 0.0005 + 0.002 + 0.03, abs=0.002) and abs(rel[1]) < 0.003
    assert math.cos(pth - th - math.pi) > math.cos(math.radians(2))
    assert math.hypot(px - start[0], py - start[1]) > 0.1  # it moved with the robot
    assert f.contact  # the part's body presses the switch while held
    # magnet off and back away: the part stays where it was left
    f = sim.step_cycle(Command(0.0, 0.0, False))
    assert not f.magnet and sim.held is None
    left = sim.part_pose(pid)
    for _ in range(20):
        sim.step_cycle(Command(-0.2, 0.0, False))
    after = sim.part_pose(pid)
    assert math.hypot(after[0] - left[0], after[1] - left[1]) < 0.003
    assert math.hypot(sim.pose[0] - after[0], sim.pose[1] - after[1]) > 0.25
    sim.close()


def test_electromagnet_ignores_a_part_seen_from_behind(field, robot):
    part = PartPlacement("R", 0.0, -0.3, 0.0)  # plate towards +x: the robot meets its back
    sim = make(field, robot, lidar=False, start_pose=(-0.2, -0.3, 0.0), extra_parts=(part,))
    for _ in range(40):
        sim.step_cycle(Command(0.1, 0.0, True))
    assert sim.held is None
    sim.close()
