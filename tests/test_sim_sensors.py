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
    """Run until the LIDAR has published a sweep whose every ray was measured after this call (SimTwo's
    whole-sweep updates: the sweep published next still holds rays measured before; the one after it
    does not), or, with ``lidar_update="per_ray"``, one period (5 cycles)."""
    frame = None
    if sim.config.lidar_update == "per_ray":
        for _ in range(5):
            frame = sim.step_cycle(cmd)
        return frame
    target = sim.lidar_sweeps + 2
    while sim.lidar_sweeps < target:
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
    # no return closer than the robot's own wheels
    assert np.all((f.ranges == -1) | (f.ranges > 0.064))
    sim.close()


def wheel_hits(robot):
    """Analytic ranges of the rays that hit the robot's own wheels (SimTwo's AGV.xml: cylinders of radius
    0.0325 m and thickness ``wheel.width`` on the axle at y = +-track/2): the scan plane cuts each wheel in
    a rectangle |x| <= sqrt(r^2 - (z - r)^2), |y| in track/2 -+ width/2; a ray meets its inner face."""
    r, half_w = robot.wheel_radius, robot.wheel["width"] / 2
    lx, ly, lz = robot.lidar.xyz
    half_chord = math.sqrt(r * r - (lz - r) ** 2)
    inner = robot.track / 2 - half_w
    out = {}
    for i, a in enumerate(robot.lidar.angles()):
        s, c = math.sin(a), math.cos(a)
        if abs(s) < 1e-9:
            continue
        t = (inner - math.copysign(ly, s)) / abs(s)
        x = lx + t * c
        if abs(x) < half_chord - 1e-4:
            out[i] = t
    return out


def test_lidar_rays_hit_the_robots_own_wheels_as_in_simtwo(field, robot):
    """SimTwo's rays are ODE rays on the base body: the wheels (separate bodies, tops 0.065 m above the
    0.05 m scan plane) are hit by the rays within about 23 degrees of +-90 degrees, at 0.0645-0.0705 m."""
    expect = wheel_hits(robot)
    angles = np.degrees(robot.lidar.angles())
    assert 80 <= len(expect) <= 100  # about 90 of 360 rays
    assert all(abs(abs(angles[i]) - 90) < 24 for i in expect)
    assert 0.064 < min(expect.values()) and max(expect.values()) < 0.0706
    for self_hits in (True, False):
        sim = make(field, robot, lidar_noise=False, lidar_self_hits=self_hits)
        sim.set_pose(0.0, -0.1, 0.3)  # in the middle of the field: nothing else within 0.2 m
        f = full_sweep(sim)
        near = set(np.flatnonzero((f.ranges > 0) & (f.ranges < 0.2)))
        if self_hits:
            assert near == set(expect)
            for i, d in expect.items():
                assert f.ranges[i] == pytest.approx(d, abs=2e-4), i
        else:  # the idealisation: rays pass through the wheels
            assert not near
        sim.close()


def test_lidar_sweeps_are_published_whole_once_per_period_and_read_0_before(field, robot):
    """SimTwo copies every ray into the values the script reads at once, when its sensor clock passes the
    period (1 ms after the frames at 200 ms, 400 ms, ...): the frames up to Tms = 200 read all 0, the
    values then change all together in the frames at Tms = 240, 440, 640, ... and in no other."""
    sim = make(field, robot, lidar_noise=True, seed=5, start_pose=(-0.62, 0.0, 0.3))
    frames = [sim.step_cycle(None) for _ in range(17)]
    sim.close()
    for f in frames[:6]:  # Tms 40 .. 240
        if f.time_ms <= 200:
            assert np.all(f.ranges == 0.0), f.time_ms
    returns = frames[5].ranges > 0
    assert returns.sum() > 200 and np.all(frames[5].ranges[~returns] == -1.0)
    for prev, f in zip(frames, frames[1:]):
        changed = f.ranges != prev.ranges
        if f.time_ms in (240, 440, 640):  # a new sweep: with noise on, every ray with a return changes
            assert changed[returns].all(), f.time_ms
        else:
            assert not changed.any(), f.time_ms


def test_lidar_per_ray_option_refreshes_rays_in_turn(field, robot):
    """``lidar_update="per_ray"`` (the idealisation): ray i of a sweep is measured 0.2 s * i / 360 after the
    sweep starts and published at once: a 40 ms cycle refreshes the next 72 rays, -1 before."""
    sim = make(field, robot, lidar_noise=True, seed=5, lidar_update="per_ray")
    first = sim.step_cycle(None)
    assert np.all(first.ranges[72:] == -1.0) and np.any(first.ranges[:72] != -1.0)
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


def simtwo_ranger_loop(n_rays, period, dt, steps):
    """A transcription of SimTwo's physics loop for one ranger2d (Viewer.pas 5416-5455, ODERobots.pas
    1593-1624 and 1842-1846) on SimTwo's own step count k: before step k the rays round(N*t/P) ..
    +round(N*dt/P)+1 are enabled and measured (we record k); after it t += dt and, when t > P, t -= P and
    the values are copied. Returns the list of (k of the copy, the k each copied value was measured at)."""
    t = 0.0
    measured_at = [None] * n_rays
    copies = []
    active = round(n_rays * dt / period) + 1
    for k in range(steps):
        first = round(n_rays * t / period)
        for i in range(n_rays):
            if first <= i <= first + active:
                measured_at[i] = k
        t = t + dt
        if t > period:
            t = t - period
            copies.append((k, list(measured_at)))
    return copies


def test_lidar_schedule_is_simtwos_loop(robot):
    """The stand-in's schedule against the transcription above: sweeps published at the same steps and
    every ray from the same step, with the stand-in's step s being SimTwo's step s - 1 (SimTwo's first
    script call comes after 39 physics steps, the stand-in's first frame after 40)."""
    from robotatfactory.sim.sensors import Lidar, simtwo_ray_steps

    spec, dt, n = robot.lidar, robot.physics_step, robot.lidar.rays
    lid = Lidar(spec, dt, 0, False, (1, 0, 0, 0, 0, 0))
    measured_at, published = {}, []
    for c in range(30):  # 1.2 s
        s0 = 40 * c
        due = lid.plan(s0, 40)
        for j, (rays, latch) in zip(due, lid._items):
            s = s0 + j + 1  # the pose after stand-in step s
            if latch:
                published.append((s, dict(measured_at)))
            for i in rays:
                measured_at[i] = s
        lid._items = None
    ref = simtwo_ranger_loop(n, spec.period, dt, 1200)
    # SimTwo copies after its step k; the stand-in after its step k + 2 (its step s ends at SimTwo's k + 1)
    assert [s for s, _ in published] == [k + 2 for k, _ in ref][:len(published)] == [201, 401, 601, 801, 1001]
    for (s, got), (k, want) in zip(published, ref):
        # a ray measured before SimTwo's step k (from the pose after k steps) = after stand-in step k + 1
        assert [got[i] for i in range(n)] == [w + 1 for w in want]
    # the helper the bridge uses: ray i of the sweep published after step 200 m + 1 is measured
    # after step 200 (m - 1) + 1 + j_i
    j = simtwo_ray_steps(n, spec.period, dt)
    s, got = published[1]
    assert [got[i] - (s - 200) for i in range(n)] == j
    assert j[0] == 0 and j[-1] == 199


def test_lidar_reports_the_sweep_measured_during_the_previous_period(field, robot):
    """Driving at 0.3 m/s towards a wall, the published range straight ahead is the distance from where the
    robot was when SimTwo measured the ray (up to 239 ms before the frame), not from where it is."""
    from robotatfactory.sim.sensors import simtwo_ray_steps

    sim = make(field, robot, lidar_noise=False, start_pose=(-0.80, 0.0, 0.0))  # facing machine A's input
    cmd = Command(0.3, 0.0, False)
    frames = [sim.step_cycle(cmd) for _ in range(26)]
    sim.close()
    i = int(np.argmin(np.abs(robot.lidar.angles())))  # the ray nearest straight ahead
    a = robot.lidar.angles()[i]
    j = simtwo_ray_steps(robot.lidar.rays, robot.lidar.period, robot.physics_step)[i]
    t = np.array([f.time_ms for f in frames], dtype=float)
    x = np.array([f.x for f in frames])
    # the frame at Tms = 1040 carries the sweep published at 1001 ms: ray i measured at 801 + j ms
    f = frames[-1]
    assert f.time_ms == 1040
    t_meas = 1040 - 239 + j
    x_meas = float(np.interp(t_meas, t, x))
    x_now = f.x
    wall = x_meas + f.ranges[i] * math.cos(a)  # the wall's face as the measured ray places it
    assert wall == pytest.approx(-0.3575, abs=0.001)  # machine A's input face: 1 mm is 3 ms at 0.3 m/s
    # the same wall from a later sweep must agree: the ranges are consistent with the measuring instants
    g = frames[-6]  # Tms 840, the sweep published at 801 ms
    x_meas_g = float(np.interp(840 - 239 + j, t, x))
    assert g.ranges[i] > f.ranges[i] + 0.05  # the robot moved ~60 mm per sweep
    assert x_meas_g + g.ranges[i] * math.cos(a) == pytest.approx(wall, abs=0.001)
    # and reading the range as if measured at the frame's own time would place the wall ~4 cm too far
    assert x_now + f.ranges[i] * math.cos(a) - wall > 0.03


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
    """The weld idealisation (magnet="weld"); SimTwo's force model: tests/test_sim_magnet.py."""
    part = PartPlacement("R", 0.0, -0.3, math.pi)  # plate towards -x, at x = -0.032
    sim = make(field, robot, lidar=False, start_pose=(-0.2, -0.3, 0.0), extra_parts=(part,), magnet="weld")
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
    # stop, magnet off and back away: the part stays where it was left (released while moving, it would glide
    # on: SimTwo's part feet have mu 0.01, so a part let go at 0.15 m/s slides ~11 cm, sim/scene.py)
    for _ in range(10):
        sim.step_cycle(Command(0.0, 0.0, True))
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
