"""The stand-in simulator's drive: SimTwo's DC motor model, the wheel speed controller, encoders, determinism."""
import math

import numpy as np
import pytest

from robotatfactory.sim import DCMotor, MotorParams, SimConfig, SpeedControllerParams, SpeedPI
from robotatfactory.sim.sensors import Encoder
from robotatfactory.simtwo import Command

# a straight, empty corridor of the field (between the machines' ribs and the outgoing warehouse)
CORRIDOR_Y = -0.38


@pytest.fixture(scope="module")
def sim(field, robot):
    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=False, competition=False, lidar=False))
    yield s
    s.close()


# ---------------------------------------------------------------------------------------------- motor model
def test_motor_current_follows_simtwos_first_order_law_with_slew_and_clamp(robot):
    p = MotorParams.from_spec(robot.motor)
    m = DCMotor(p, 0.001)
    a = math.exp(-0.001 * p.R / p.L)
    # a small step: no slew limit, plain first order towards V/R
    m.step(0.5, 0.0)
    assert m.current == pytest.approx((1 - a) * 0.5 / p.R, rel=1e-12)
    # a large step is slew-limited to 0.5 A per step
    m.reset()
    m.step(8.2, 0.0)
    assert m.current == pytest.approx(p.slew_A_per_step)
    # the voltage is clamped to +-Vmax: 100 V acts as 8.2 V
    m2 = DCMotor(p, 0.001)
    for _ in range(50):
        m.step(8.2, 0.0)
        m2.step(100.0, 0.0)
    assert m2.voltage == p.Vmax
    assert m2.current == pytest.approx(m.current)
    assert m.current == pytest.approx(p.Vmax / p.R, rel=1e-6)  # stall current 1.34 A
    # back-EMF adds to a reversed voltage: -(8.2 + Ke*40)/R = -3.04 A is clamped to -Imax
    m.reset()
    for _ in range(100):
        m.step(-8.2, 40.0)
    assert m.current == pytest.approx(-p.Imax)
    # SimTwo's torque law
    assert m.torque(40.0) == pytest.approx(p.Kt * -p.Imax - p.Bv * 40.0 - p.Fc)


def test_speed_pi_ramps_the_reference_and_does_not_wind_up(robot):
    cp = SpeedControllerParams.from_spec(robot.speed_controller)
    pi = SpeedPI(cp, 8.2)
    pi.target = 10.0
    u = pi.update(0.0)
    assert pi.ref == pytest.approx(cp.accel_limit * cp.period)
    for _ in range(5000):  # a stalled wheel: the output saturates, the integral stops growing
        u = pi.update(0.0)
    assert u == 8.2
    integral = pi.integral
    pi.update(0.0)
    assert pi.integral == integral
    assert pi.integral < 8.2


def test_free_robot_at_full_voltage_reaches_simtwos_no_load_speed(sim, robot):
    """Open loop at 8.2 V the robot settles where Kt*(V - Ke*w)/R = Bv*w + Fc: 27.2 rad/s, 0.88 m/s
    (SimTwo's "about 1 m/s")."""
    p = MotorParams.from_spec(robot.motor)
    w_theory = p.no_load_speed(8.2)
    assert w_theory == pytest.approx((p.Kt * 8.2 / p.R - p.Fc) / (p.Kt * p.Ke / p.R + p.Bv))
    assert 0.8 < w_theory * robot.wheel_radius < 1.0
    sim.set_pose(-0.78, CORRIDOR_Y, 0.0)
    sim.drive_voltages(8.2, 8.2)
    for _ in range(20):  # 0.8 s: the mechanical time constant is ~50 ms
        sim.step_cycle(None)
    wl, wr = sim.wheel_speeds
    v, w = sim.body_velocity
    assert wl == pytest.approx(w_theory, rel=0.02) and wr == pytest.approx(w_theory, rel=0.02)
    assert v == pytest.approx(w_theory * robot.wheel_radius, rel=0.02)  # rolling, not slipping
    assert abs(w) < 0.01
    assert sim.motor_voltages == (8.2, 8.2)


# ---------------------------------------------------------------------------------------------- control
@pytest.mark.parametrize("v,w", [(0.3, 0.0), (0.5, 0.0), (-0.2, 0.0), (0.0, 4.0), (0.0, -2.5), (0.2, 1.5),
                                 (0.4, -1.0), (0.05, 0.3)])
def test_steady_state_wheel_speeds_track_v_w_within_2_percent(sim, robot, v, w):
    x0 = -0.6 if v >= 0 else 0.6
    if abs(w) > 0.5:
        x0 = 0.0
    sim.set_pose(x0, CORRIDOR_Y if abs(w) <= 0.5 else -0.3, 0.0)
    sim.apply(Command(v, w, False))
    for _ in range(15):  # 0.6 s: ramp (60 rad/s^2) and settling
        sim.step_cycle(None)
    samples = []
    for _ in range(5):
        sim.step_cycle(None)
        samples.append(sim.wheel_speeds)
    got = np.mean(samples, axis=0)
    want = np.array(robot.wheel_speeds(v, w))
    assert np.all(np.abs(got - want) <= 0.02 * np.abs(want) + 1e-3), (got, want)
    bv, bw = sim.body_velocity
    assert bv == pytest.approx(v, abs=0.02 * abs(v) + 2e-3)
    assert bw == pytest.approx(w, abs=0.02 * abs(w) + 5e-3)


def test_robot_drives_straight_when_commanded_straight(sim):
    sim.set_pose(-0.7, CORRIDOR_Y, 0.0)
    for _ in range(40):  # 1.6 s at 0.3 m/s: about 0.45 m
        sim.step_cycle(Command(0.3, 0.0, False))
    x, y, th = sim.pose
    assert x > -0.3
    assert abs(y - CORRIDOR_Y) < 0.001
    assert abs(th) < math.radians(0.1)
    sim.set_pose(0.7, CORRIDOR_Y, 0.0)
    for _ in range(40):
        sim.step_cycle(Command(-0.3, 0.0, False))
    x, y, th = sim.pose
    assert x < 0.3 and abs(y - CORRIDOR_Y) < 0.001 and abs(th) < math.radians(0.1)


def test_fast_loop_is_the_reference_loop(field, robot):
    """The inlined hot loop computes exactly what DCMotor/SpeedPI compute."""
    from robotatfactory.sim import Simulator

    runs = []
    for reference in (True, False):
        s = Simulator(field, robot, SimConfig(camera=False, competition=True, lidar=True), reference_drive=reference)
        runs.append([s.step_cycle(Command(0.3 * math.sin(i / 9), 1.5 * math.cos(i / 7), False)) for i in range(60)])
        s.close()
    assert runs[0] == runs[1]


# ---------------------------------------------------------------------------------------------- encoders
def test_encoder_reports_floor_of_accumulated_fraction_and_carries_the_rest():
    enc = Encoder(360, 0.0)
    per_tick = 2 * math.pi / 360
    deltas = [enc.update(per_tick * 0.4 * (k + 1)) for k in range(10)]  # 0.4 tick per cycle
    assert deltas == [0, 0, 1, 0, 1, 0, 0, 1, 0, 1]
    assert enc.total == 4 and enc.fraction == pytest.approx(0.0, abs=1e-9)
    back = [enc.update(per_tick * (4.0 - 0.7 * (k + 1))) for k in range(3)]  # backwards 0.7 tick per cycle
    assert back == [-1, -1, -1] and enc.total == 1 == math.floor(4.0 - 2.1)  # the total is floor(angle in ticks)
    assert sum(deltas) + sum(back) == enc.total


def test_encoder_ticks_match_ground_truth_wheel_travel(field, robot):
    import mujoco

    from robotatfactory.sim import Simulator

    s = Simulator(field, robot, SimConfig(camera=False, competition=False, lidar=False, start_pose=(-0.6, CORRIDOR_Y, 0.0)))
    m, d = s.model, s.data
    wheel_bodies = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in ("wheel_left", "wheel_right")]
    last = [d.xpos[b].copy() for b in wheel_bodies]
    travel = np.zeros(2)
    totals = np.zeros(2, dtype=int)
    commands = [Command(0.25, 0.0, False)] * 30 + [Command(0.15, 1.2, False)] * 30 + [Command(-0.1, -0.5, False)] * 15
    for cmd in commands:
        f = s.step_cycle(cmd)
        assert f.enc_total[0] == totals[0] + f.enc_delta[0] and f.enc_total[1] == totals[1] + f.enc_delta[1]
        totals[:] = f.enc_total
        _, _, th = s.pose
        heading = np.array([math.cos(th), math.sin(th), 0.0])
        for i, b in enumerate(wheel_bodies):  # signed path of each wheel's centre along the heading
            p = d.xpos[b].copy()
            travel[i] += float((p - last[i]) @ heading)
            last[i] = p
    s.close()
    ticks_m = totals * robot.metres_per_tick
    assert np.all(travel > 0.2)
    # within one tick (0.57 mm) plus 0.3 % (the tyre's contact patch and sub-mm creep)
    assert np.all(np.abs(ticks_m - travel) <= robot.metres_per_tick + 0.003 * np.abs(travel)), (ticks_m, travel)


def test_same_seed_same_run_different_seed_different_lidar_noise(field, robot):
    from robotatfactory.sim import Simulator

    def run(seed):
        s = Simulator(field, robot, SimConfig(seed=seed, camera=False, competition=True, lidar=True))
        frames = [s.step_cycle(Command(0.2, 0.8 * math.sin(i / 5), i > 20)) for i in range(30)]
        s.close()
        return frames

    a, b, c = run(3), run(3), run(4)
    assert a == b
    assert [f.x for f in a] == [f.x for f in c]  # the physics does not depend on the seed
    assert any(not np.array_equal(fa.ranges, fc.ranges) for fa, fc in zip(a, c))


def test_speed_pi_is_stable_on_a_lifted_wheel(robot):
    """A wheel off the ground has only its own inertia (2.6e-5 kg.m^2): the 1 ms loop must not ring."""
    p = MotorParams.from_spec(robot.motor)
    cp = SpeedControllerParams.from_spec(robot.speed_controller)
    pi, motor = SpeedPI(cp, p.Vmax), DCMotor(p, 0.001)
    inertia = 0.5 * robot.wheel["mass"] * robot.wheel_radius ** 2
    w, trace = 0.0, []
    pi.target = 10.0
    for _ in range(1000):
        torque = motor.step(pi.update(w), w) - p.Bv * w - math.copysign(p.Fc, w) * (w != 0)
        w += torque / inertia * 0.001
        trace.append((w, pi.output))
    trace = np.array(trace[-300:])
    assert np.ptp(trace[:, 0]) < 0.01 and abs(trace[-1, 0] - 10.0) < 0.01
    assert np.ptp(trace[:, 1]) < 0.05  # no voltage chatter


def test_circle_is_driven_round_and_round(sim, robot):
    """Ten seconds on a 0.18 m circle round the field's centre: the path stays on the circle."""
    v, w = 0.108, 0.6
    sim.set_pose(0.0, -0.1, 0.0)
    centre = np.array([0.0, -0.1 + v / w])
    radii = []
    for k in range(250):
        sim.step_cycle(Command(v, w, False))
        if k > 15:
            radii.append(np.linalg.norm(np.array(sim.pose[:2]) - centre))
    assert np.max(np.abs(np.array(radii) - v / w)) < 0.004
    assert sim.data.ncon == 3  # two wheels and the caster on the floor, nothing else
