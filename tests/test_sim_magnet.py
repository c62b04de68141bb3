"""The stand-in's electromagnet as SimTwo computes it (``SimConfig.magnet="force"``, the default) against the
weld idealisation (``magnet="weld"``). SimTwo's law (ODERobots.pas 1635-1650, AGV.xml 197-205): a pull of
0.5*Vin*fmax/(1 + k2*d)^2 = 5 N towards the ray's origin, at the part's centre of mass, while the solenoid's
one 2 cm ray meets a part's ferromagnetic plate; see robotatfactory/sim/magnet.py and docs/simulator.md.

Geometry used below: the magnet's face is 0.08 m ahead of base_link; a part's plate stands 2 mm proud of its
0.06 m deep body, so a part touching the magnet has its centre 0.112 m ahead of base_link. SimTwo's ray starts
5 mm behind the face and is 2 cm long: it reaches 15 mm beyond the face.
"""
import math

import numpy as np
import pytest

from robotatfactory.sim import PartPlacement, SimConfig
from robotatfactory.simtwo import Command

TOUCH = 0.08 + 0.002 + 0.03  # m: base_link to the centre of a part whose plate touches the magnet
A_MAX, ALPHA_MAX = 0.8, 11.85  # the competition agent's limits (agent/follower.py DriveLimits.from_robot)


def make(field, robot, gap, magnet="force", facing_off=0.0, y=0.0):
    """A robot at the origin heading +x and one part ahead whose plate is ``gap`` m from the magnet's face."""
    from robotatfactory.sim import Simulator

    part = PartPlacement("R", TOUCH + gap, y, math.pi + facing_off)
    return Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False, magnet=magnet,
                                             start_pose=(0.0, 0.0, 0.0), extra_parts=(part,)))


def rel(sim):
    """The part's pose in the robot's frame: (x ahead, y left, yaw of its plate's normal against -x, rad)."""
    pid = sim.parts.ids[0]
    x, y, th = sim.pose
    px, py, pth = sim.part_pose(pid)
    r = np.array([[math.cos(th), math.sin(th)], [-math.sin(th), math.cos(th)]]) @ np.array([px - x, py - y])
    return float(r[0]), float(r[1]), math.remainder(pth - th - math.pi, 2 * math.pi)


def ramp(v0, w0, v1, w1, hold, a=A_MAX, alpha=ALPHA_MAX, dt=0.04):
    """Commands from (v0, w0) to (v1, w1) within the acceleration limits, then ``hold`` cycles at (v1, w1)."""
    out, v, w = [], v0, w0
    while abs(v - v1) > 1e-9 or abs(w - w1) > 1e-9:
        v += max(-a * dt, min(a * dt, v1 - v))
        w += max(-alpha * dt, min(alpha * dt, w1 - w))
        out.append((v, w))
    return out + [(v1, w1)] * hold


def drive(sim, profile, magnet=True):
    """Run the profile; returns the largest |lateral offset| of the part (m) and whether the magnet ever let
    go of it (``held`` None while on)."""
    worst, lost = 0.0, False
    for v, w in profile:
        sim.step_cycle(Command(v, w, magnet))
        worst = max(worst, abs(rel(sim)[1]))
        lost = lost or sim.held is None
    return worst, lost


def test_force_is_simtwos_law_along_the_ray_at_the_centre_of_mass(field, robot):
    from robotatfactory.sim.magnet import MagnetParams

    p = MagnetParams.from_spec(robot.electromagnet)
    assert (p.fmax, p.k2, p.vin_on, p.beam, p.ray_behind_face, p.period) == (10.0, 0.5, 1.0, 0.02, 0.005, 0.01)
    for d in (0.0, 0.005, 0.012, 0.02):
        assert p.force(1.0, d) == pytest.approx(0.5 * 1.0 * 10.0 / (1.0 + 0.5 * d) ** 2, rel=1e-12)
    assert p.force(1.0, -0.001) == p.force(1.0, 0.0) and p.force(0.0, 0.005) == 0.0

    sim = make(field, robot, gap=0.004)
    pid = sim.parts.ids[0]
    sim.step_cycle(Command(0.0, 0.0, True))
    mg = sim._magnet
    assert sim.held == pid
    # the pull of the last step: SimTwo's magnitude for the ray's distance, towards the robot (world -x here)
    assert np.linalg.norm(mg.last_force) == pytest.approx(p.force(1.0, mg.dist), rel=1e-9)
    assert mg.last_force[0] < -4.9 and abs(mg.last_force[1]) < 0.05 and abs(mg.last_force[2]) < 0.05
    body = sim.parts.body[pid]
    xfrc = sim.data.xfrc_applied
    assert np.allclose(xfrc[body, :3], mg.last_force) and np.allclose(xfrc[body, 3:], 0.0)  # no torque
    assert np.allclose(xfrc[sim._robot_body, :3], -mg.last_force)  # the reaction on the robot
    sim.close()


def test_attracts_a_part_from_a_few_mm(field, robot):
    sim = make(field, robot, gap=0.004)
    start = rel(sim)
    for _ in range(5):  # magnet off: the part stays where it is
        sim.step_cycle(Command(0.0, 0.0, False))
    assert abs(rel(sim)[0] - start[0]) < 2e-4 and sim.held is None
    for _ in range(10):
        sim.step_cycle(Command(0.0, 0.0, True))
    x, y, _ = rel(sim)
    assert x == pytest.approx(TOUCH, abs=0.001) and abs(y) < 0.001  # pulled in against the magnet's face
    assert sim.held == sim.parts.ids[0]
    sim.close()


@pytest.mark.parametrize("magnet", ["force", "weld"])
def test_does_not_attract_from_beyond_the_ray(field, robot, magnet):
    """18 mm: beyond SimTwo's ray (15 mm past the face). The weld's beam reached 20 mm: it grabbed the part."""
    sim = make(field, robot, gap=0.018, magnet=magnet)
    start = rel(sim)
    for _ in range(25):
        sim.step_cycle(Command(0.0, 0.0, True))
    moved = abs(rel(sim)[0] - start[0])
    if magnet == "force":
        assert sim.held is None and moved < 5e-4
    else:
        assert sim.held is not None and moved > 0.015
    sim.close()


def test_releases_the_part_when_switched_off(field, robot):
    sim = make(field, robot, gap=0.003)
    for _ in range(10):
        sim.step_cycle(Command(0.0, 0.0, True))
    assert sim.held is not None
    sim.step_cycle(Command(0.0, 0.0, False))
    assert sim.held is None and np.allclose(sim.data.xfrc_applied, 0.0)
    pid = sim.parts.ids[0]
    left = sim.part_pose(pid)
    for _ in range(20):
        sim.step_cycle(Command(-0.2, 0.0, False))
    after = sim.part_pose(pid)
    assert math.hypot(after[0] - left[0], after[1] - left[1]) < 0.002  # not dragged along
    assert rel(sim)[0] > TOUCH + 0.1
    sim.close()


def test_holds_a_part_in_straight_driving_at_carrying_speeds(field, robot):
    """0.4 m/s forwards and backwards, accelerating at the agent's 0.8 m/s^2 and with unramped steps from and to
    rest: the part never leaves the magnet's face (measured: no lateral slide at all). (A step straight from
    +0.4 to -0.4 m/s lost it with the earlier part-floor friction 0.4: the robot pitched ~8 deg nose down and
    the ray dipped below the plate; with SimTwo's part feet it holds.)"""
    sim = make(field, robot, gap=0.002)
    for _ in range(5):
        sim.step_cycle(Command(0.0, 0.0, True))
    profile = ramp(0, 0, 0.4, 0, 15) + ramp(0.4, 0, 0, 0, 5) + ramp(0, 0, -0.4, 0, 15) + ramp(-0.4, 0, 0, 0, 5)
    # unramped steps from and to rest (SimTwo's PID alone): still held
    profile += [(0.4, 0.0)] * 15 + [(0.0, 0.0)] * 10 + [(-0.4, 0.0)] * 15 + [(0.0, 0.0)] * 10
    worst, lost = drive(sim, profile)
    assert not lost and worst < 0.001
    assert rel(sim)[0] == pytest.approx(TOUCH, abs=0.001)
    sim.close()


def test_in_an_arc_the_force_holds_the_part(field, robot):
    """An arc at 0.4 m/s turning at up to 3 rad/s (the agent's limits): SimTwo's force holds the part, which
    slides sideways on the magnet's face by about a millimetre (measured 0.7 mm with SimTwo's part feet, mu
    0.01; about 8 mm with the stand-in's earlier part-floor friction 0.4, whose drag pulled it sideways);
    the weld moves not at all."""
    slides = {}
    for magnet in ("force", "weld"):
        sim = make(field, robot, gap=0.002, magnet=magnet)
        for _ in range(5):
            sim.step_cycle(Command(0.0, 0.0, True))
        worst, lost = drive(sim, ramp(0, 0, 0.4, 0, 5) + ramp(0.4, 0, 0.4, 3.0, 20) + ramp(0.4, 3.0, 0, 0, 10))
        assert not lost, magnet
        slides[magnet] = worst
        sim.close()
    assert slides["weld"] < 5e-4
    assert slides["force"] < 0.01


@pytest.mark.parametrize("magnet", ["force", "weld"])
def test_turning_on_the_spot_slides_the_part_the_weld_keeps_it_still(field, robot, magnet):
    """Turning on the spot at the agent's 3 rad/s (ramped at 11.85 rad/s^2): on SimTwo's part feet (mu 0.01,
    modelled frictionless, sim/scene.py) the part's inertia alone needs ~0.3 N, less than the magnet face's
    friction (mu 0.1 x 5 N) gives: the force keeps it, sliding sideways along the face by centimetres
    (measured 33 mm). The weld holds it still."""
    sim = make(field, robot, gap=0.002, magnet=magnet)
    for _ in range(5):
        sim.step_cycle(Command(0.0, 0.0, True))
    worst, lost = drive(sim, ramp(0, 0, 0, 3.0, 25) + ramp(0, 3.0, 0, 0, 5))
    assert not lost and sim.held is not None
    if magnet == "force":
        assert 0.005 < worst < 0.04
    else:
        assert worst < 5e-4
    sim.close()


def test_with_a_part_floor_friction_of_0_4_turning_on_the_spot_loses_the_part(field, robot, monkeypatch):
    """What SimTwo's low part-feet friction decides: with the stand-in's earlier part-floor friction 0.4 the
    floor's drag (0.4 x 0.21 kg x 9.81 = 0.8 N) exceeds the face's friction (0.5 N) and a turn on the spot at
    3 rad/s drags the part off the magnet: it slides sideways until the ray misses its plate."""
    import robotatfactory.sim.scene as scene

    monkeypatch.setattr(scene, "PART_FOOT_FRICTION", (0.4, 0.005, 0.0001))
    sim = make(field, robot, gap=0.002)
    for _ in range(5):
        sim.step_cycle(Command(0.0, 0.0, True))
    worst, lost = drive(sim, ramp(0, 0, 0, 3.0, 25) + ramp(0, 3.0, 0, 0, 5))
    assert lost and sim.held is None
    assert math.hypot(*rel(sim)[:2]) > TOUCH + 0.02 or abs(rel(sim)[1]) > 0.04  # no longer on the magnet
    sim.close()


def test_a_glancing_collision_knocks_the_part_off_centre(field, robot):
    """Carrying at 0.4 m/s into a free part standing 5 cm to the side of the path, stopping short of machine B's
    wall: the carried part is knocked sideways along the magnet's face (measured 34 mm and 0.27 rad with
    SimTwo's part feet, 15 mm with the earlier part-floor friction 0.4) and stays on it; the weld does not let it
    move. (Driving on into the wall, the free part, which now slides easily, is pushed ahead and jammed between
    the carried part and the wall, which knocks the carried part off.)"""
    from robotatfactory.sim import Simulator

    shifts = {}
    for magnet in ("force", "weld"):
        # from x = -0.2 towards machine B's wall (x = 0.337): the obstacle stands at x = 0.25
        parts = (PartPlacement("R", -0.2 + TOUCH + 0.002, 0.0, math.pi), PartPlacement("G", 0.25, 0.05, 0.0))
        sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False, magnet=magnet,
                                                start_pose=(-0.2, 0.0, 0.0), extra_parts=parts))
        for _ in range(5):
            sim.step_cycle(Command(0.0, 0.0, True))
        obstacle = sim.part_pose(sim.parts.ids[1])
        drive(sim, ramp(0, 0, 0.4, 0, 8) + ramp(0.4, 0, 0, 0, 5))  # stops at x = 0.1: the part 0.04 m from the wall
        moved = sim.part_pose(sim.parts.ids[1])
        assert math.hypot(moved[0] - obstacle[0], moved[1] - obstacle[1]) > 0.003  # it was hit and pushed
        assert sim.held == sim.parts.ids[0], magnet
        shifts[magnet] = abs(rel(sim)[1])
        sim.close()
    assert shifts["weld"] < 5e-4
    assert shifts["force"] > 0.005


def test_a_part_seen_from_behind_is_not_pulled(field, robot):
    """The ray's nearest hit is the part's body, not its plate: not ferromagnetic, no pull (SimTwo's
    UpdateMeasures tests the hit solid's <ferromagnetic/>)."""
    sim = make(field, robot, gap=0.003, facing_off=math.pi)  # plate away from the robot
    start = sim.part_pose(sim.parts.ids[0])
    for _ in range(15):
        sim.step_cycle(Command(0.0, 0.0, True))
    now = sim.part_pose(sim.parts.ids[0])
    assert sim.held is None and sim._magnet.value == 0
    assert math.hypot(now[0] - start[0], now[1] - start[1]) < 2e-4
    sim.close()


def test_force_mode_is_deterministic_and_the_reference_loop_matches(field, robot):
    """Same commands, same frames and part poses; the plain reference loop gives the same run as the inlined
    one with the magnet's per-step force."""
    from robotatfactory.sim import Simulator

    runs = []
    for reference in (False, False, True):
        part = PartPlacement("R", TOUCH + 0.004, 0.0, math.pi)
        sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False,
                                                start_pose=(0.0, 0.0, 0.0), extra_parts=(part,)),
                        reference_drive=reference)
        out = []
        for v, w in [(0.0, 0.0)] * 5 + ramp(0, 0, 0.3, 1.5, 10):
            f = sim.step_cycle(Command(v, w, True))
            out.append((f.x, f.y, f.theta, f.enc_total, sim.part_pose(sim.parts.ids[0]), sim.held))
        runs.append(out)
        sim.close()
    assert runs[0] == runs[1] == runs[2]


def test_several_robots_each_magnet_pulls_its_own_part(field, robot):
    """step_all: every robot's magnet runs its own ray and force (robot 2's part is pulled by robot 2)."""
    from robotatfactory.sim import Simulator

    parts = (PartPlacement("R", TOUCH + 0.004, 0.0, math.pi), PartPlacement("G", TOUCH + 0.004, 0.4, math.pi))
    sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False, robots=2,
                                            start_poses=((0.0, 0.0, 0.0), (0.0, 0.4, 0.0)), extra_parts=parts))
    p1, p2 = sim.parts.ids
    for _ in range(10):
        sim.step_all([Command(0.0, 0.0, False), Command(0.0, 0.0, True)])
    assert sim.units[0].held is None and sim.units[1].held == p2
    assert sim.part_pose(p1)[0] == pytest.approx(TOUCH + 0.004, abs=3e-4)  # robot 1's magnet is off
    assert sim.part_pose(p2)[0] == pytest.approx(TOUCH, abs=0.001)
    sim.close()
