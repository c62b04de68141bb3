"""Docking on the bare stand-in simulator: pick a part from a warehouse slot and place it in another,
and a failed pick (no part) detected. The simulator's ground-truth pose stands in for the EKF only here."""
import math
from dataclasses import replace

import pytest

from robotatfactory.agent.settings import Carrying
from robotatfactory.agent.docking import Docker
from robotatfactory.agent.follower import DriveLimits, PathFollower
from robotatfactory.agent.footprint import carrying_footprint, dock_distance, robot_footprint
from robotatfactory.agent.obstacles import FieldObstacles, PartObstacle
from robotatfactory.agent.planner import PathPlanner
from robotatfactory.sim import SimConfig
from robotatfactory.simtwo import Command


class Run:
    """The agent's pieces wired by hand around a Simulator (what the ROS node will do with topics)."""

    def __init__(self, sim, field, robot):
        self.sim, self.field, self.robot = sim, field, robot
        self.limits = DriveLimits.from_robot(robot)
        # carrying: the agent's gentler limits (a part on SimTwo's magnet slides on its face in fast turns)
        self.carry_limits = replace(self.limits, w_max=Carrying.w_max, alpha_max=Carrying.alpha_max,
                                    v_max=Carrying.v_max)
        self.follower = PathFollower(self.limits, robot.control_period)
        self.docker = Docker(self.limits, robot.control_period, robot.electromagnet["x"], field.part)
        self.magnet = False
        self.contact = False
        self.log = []

    def cycle(self, v, w, magnet):
        self.magnet = magnet
        frame = self.sim.step_cycle(Command(v, w, magnet))
        self.contact = frame.contact

    def goto(self, pose, footprint, parts):
        pl = PathPlanner(FieldObstacles(self.field, parts))
        path = pl.plan(self.sim.pose[:2], pose[:2], footprint)
        self.follower.limits = self.carry_limits if self.magnet else self.limits  # the magnet on: carrying
        self.follower.start(path.points, final_heading=pose[2])
        for _ in range(2000):
            o = self.follower.step(self.sim.pose)
            self.cycle(o.v, o.w, self.magnet)
            if o.done:
                return
        raise AssertionError("goto timed out")

    def dock(self, start, slot, retreat):
        start(slot, self.sim.pose, retreat)
        for _ in range(1000):
            o = self.docker.step(self.sim.pose, self.contact)
            self.log.append((self.sim.time, o.phase, self.contact, self.sim.held))
            self.cycle(o.v, o.w, o.magnet)
            if o.done or o.failed:
                return o
        raise AssertionError("dock timed out")


def _slot_axes(facing: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """A slot's unit vectors: u out of the slot, n the robot's left as it faces the slot."""
    return (math.cos(facing), math.sin(facing)), (math.sin(facing), -math.cos(facing))


@pytest.fixture
def make_sim(field, robot):
    sims = []

    def make(**kw):
        from robotatfactory.sim import Simulator

        s = Simulator(field, robot, SimConfig(camera=False, lidar=False, **kw))
        sims.append(s)
        return s
    yield make
    for s in sims:
        s.close()


def test_pick_from_incoming_and_place_in_outgoing(make_sim, field, robot):
    # the simulator's default magnet: SimTwo's force (docs/simulator.md, "The electromagnet")
    sim = make_sim(round_no=1, parts="XBXX")
    run = Run(sim, field, robot)
    fp, fc = robot_footprint(robot), carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    src, dst = field.slot("incoming", 2), field.slot("outgoing", 3)
    parts = [PartObstacle(*src.xy, src.facing)]
    pl = PathPlanner(FieldObstacles(field, parts))
    run.goto(pl.approach_pose(src, d, fp), fp, parts)
    retreat = math.hypot(*(a - b for a, b in zip(PathPlanner(FieldObstacles(field, [])).approach_pose(src, d, fc)[:2],
                                                   src.xy)))
    o = run.dock(run.docker.start_pick, src, retreat)
    assert o.done and not o.failed and sim.held == 2 and run.contact  # part ids are the incoming slot numbers
    t_pick = sim.time
    pl_c = PathPlanner(FieldObstacles(field, []))
    run.goto(pl_c.approach_pose(dst, d, fc), fc, [])
    assert sim.held == 2, "the part was lost on the way"
    o = run.dock(run.docker.start_place, dst, math.hypot(*(a - b for a, b in zip(pl_c.approach_pose(dst, d, fp)[:2],
                                                                              dst.xy))))
    assert o.done and not o.failed and sim.held is None and not run.contact
    px, py, pth = sim.part_pose(2)
    err = math.hypot(px - dst.xy[0], py - dst.xy[1])
    print(f"picked at t = {t_pick:.2f} s, placed at t = {sim.time:.2f} s, {err * 1000:.1f} mm from the slot centre, "
          f"plate heading off by {math.degrees(math.remainder(pth - dst.facing, 2 * math.pi)):.1f} deg")
    assert err < 0.01  # the rules allow 3 cm
    rep = sim.referee.report(sim.time)
    assert rep.points == 1 == rep.max_points


def test_no_part_no_contact_is_a_failure(make_sim, field, robot):
    sim = make_sim(round_no=1, parts="BXXX")  # incoming slot 3 is empty
    run = Run(sim, field, robot)
    fp = robot_footprint(robot)
    d = dock_distance(robot, field.part)
    slot = field.slot("incoming", 3)
    pl = PathPlanner(FieldObstacles(field, []))
    ap = pl.approach_pose(slot, d, fp)
    sim.set_pose(*ap)
    o = run.dock(run.docker.start_pick, slot, 0.2)
    assert o.failed == "no_contact" and sim.held is None and not run.magnet
    # it stopped short of the rib ends: the base never touched the warehouse
    assert not FieldObstacles(field, []).collides(fp, sim.pose)


def test_an_aborted_pick_backs_out_first(make_sim, field, robot):
    sim = make_sim(round_no=1, parts="XBXX")
    run = Run(sim, field, robot)
    fp = robot_footprint(robot)
    d = dock_distance(robot, field.part)
    slot = field.slot("incoming", 2)
    ap = PathPlanner(FieldObstacles(field, [PartObstacle(*slot.xy, slot.facing)])).approach_pose(slot, d, fp)
    sim.set_pose(*ap)
    run.docker.start_pick(slot, sim.pose, 0.2)
    for _ in range(10):  # part of the way in
        o = run.docker.step(sim.pose, run.contact)
        run.cycle(o.v, o.w, o.magnet)
    run.docker.abort(sim.pose)
    vs = []
    for _ in range(300):
        o = run.docker.step(sim.pose, run.contact)
        vs.append(o.v)
        run.cycle(o.v, o.w, o.magnet)
        if o.failed or o.done:
            break
    assert o.failed == "timeout" and not o.magnet and sim.held is None
    assert min(vs) < 0 and max(vs) <= 0  # only backwards
    assert math.hypot(sim.pose[0] - slot.xy[0], sim.pose[1] - slot.xy[1]) == pytest.approx(0.2, abs=0.005)


@pytest.mark.parametrize("lateral_mm,turn_deg,out_mm", [(11, -3, 9), (-7, 3, 6)])
def test_a_part_standing_out_of_its_slot_turned_is_pressed_square_before_the_grip(make_sim, field, robot, lateral_mm,
                                                                                  turn_deg, out_mm):
    """A part put into its slot as a referee would (6-9 mm out from the back wall, 7-11 mm to the side, turned 3
    deg; issue 20's perturbed world), the robot docking along the slot's nominal normal: with the magnet on from the
    approach's start and a stop at the contact, the magnet's pull met the plate off-centre and the part pivoted
    15 deg on the face's edge (then caught a rib backing out: picks lost in round 1). With the press (the robot
    drives on to the dock pose, the magnet off, then grips) the part is squared against the back wall: held,
    square on the face."""
    from robotatfactory.agent.docking import DockSettings

    slot = field.slot("incoming", 3)
    fp, fc = robot_footprint(robot), carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    ap = PathPlanner(FieldObstacles(field, [PartObstacle(*slot.xy, slot.facing)])).approach_pose(slot, d, fp)
    retreat = math.hypot(*(a - b for a, b in zip(
        PathPlanner(FieldObstacles(field, [])).approach_pose(slot, d, fc)[:2], slot.xy)))
    u, n = _slot_axes(slot.facing)
    lat, out = lateral_mm / 1000, out_mm / 1000  # to the robot's left; out from the back wall
    twist = {}
    for name, settings in (("stop at contact", DockSettings(magnet_early=True, press_time=0.0)),
                           ("press", DockSettings(magnet_early=False, press_time=0.4))):
        sim = make_sim(round_no=1, parts="XXBX")
        sim.place_part(3, slot.xy[0] + lat * n[0] + out * u[0], slot.xy[1] + lat * n[1] + out * u[1],
                       slot.facing + math.radians(turn_deg))
        sim.set_pose(*ap)
        run = Run(sim, field, robot)
        run.docker = Docker(run.limits, robot.control_period, robot.electromagnet["x"], field.part, settings)
        run.docker.start_pick(slot, sim.pose, retreat)
        turned = []  # deg: the part against the magnet's face, each cycle
        for _ in range(1000):
            o = run.docker.step(sim.pose, run.contact)
            run.cycle(o.v, o.w, o.magnet)
            if o.phase != "approach":  # from the contact on
                turned.append(abs(math.degrees(math.remainder(sim.part_pose(3)[2] - (sim.pose[2] + math.pi),
                                                              2 * math.pi))))
            if o.done or o.failed:
                break
        twist[name] = (max(turned), turned[-1])  # the most from the contact on; at the end
        if name == "press":
            assert o.done and not o.failed and sim.held == 3 and run.contact
    assert twist["press"][1] < 3.0, twist  # square on the face at the end
    # the case provokes the pivot without the press (whether backing out squares it again or turns it on to 15 deg
    # hangs on a tenth of a millimetre)
    assert twist["stop at contact"][0] > 5.0, twist


@pytest.mark.parametrize("turn_deg", [5.0, -5.0])
def test_the_offset_held_is_the_parts_from_the_magnets_centre_line_not_base_links(make_sim, field, robot, turn_deg):
    """Turned at the contact, base_link stands off the slot's normal while the magnet's centre is on the part:
    the offset the place repeats is where the robot's centre line crosses the part, not base_link's. Taking
    base_link's (14 mm, turned 7.6 deg) placed a part 14 mm off and into a rib (round 3 seed 100). Backing out
    goes on along base_link's line."""
    slot = field.slot("incoming", 3)
    fc = carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    retreat = math.hypot(*(a - b for a, b in zip(
        PathPlanner(FieldObstacles(field, [])).approach_pose(slot, d, fc)[:2], slot.xy)))
    u, n = _slot_axes(slot.facing)
    psi = math.radians(turn_deg)
    along = d + 0.012
    lat = -along * math.tan(psi)  # base_link off the normal, its centre line through the slot's centre
    sim = make_sim(round_no=1, parts="XXBX")
    sim.set_pose(slot.xy[0] + along * u[0] + lat * n[0], slot.xy[1] + along * u[1] + lat * n[1],
                 slot.facing + math.pi + psi)
    run = Run(sim, field, robot)
    run.docker.start_pick(slot, sim.pose, retreat)
    swing = 0.0  # m: the part's largest offset from the slot's normal backing out, within 7 cm of the slot
    for _ in range(1000):
        o = run.docker.step(sim.pose, run.contact)
        run.cycle(o.v, o.w, o.magnet)
        px, py, _ = sim.part_pose(3)
        if o.phase == "back" and (px - slot.xy[0]) * u[0] + (py - slot.xy[1]) * u[1] < 0.07:
            swing = max(swing, abs((px - slot.xy[0]) * n[0] + (py - slot.xy[1]) * n[1]))
        if o.done or o.failed:
            break
    assert o.done and not o.failed and sim.held == 3
    x, y, th = sim.pose
    px, py, _ = sim.part_pose(3)
    right_of_centre_line = (px - x) * math.sin(th) - (py - y) * math.cos(th)  # the part's, on the magnet now
    assert abs(lat) > 0.008  # the case: base_link well off the normal
    assert run.docker.held_offset == pytest.approx(right_of_centre_line, abs=0.003), (lat, right_of_centre_line)
    # backing out along the normal through base_link, not onto the centre line's: steering onto it turned the
    # robot in the slot and swung the part 13 mm (whole stack: against machine A's rib, round 3 seeds 107, 113)
    assert swing < 0.010, swing


@pytest.mark.parametrize("lateral_mm,placed", [(24, False), (-24, False), (6, True)])
def test_a_place_that_would_meet_a_rib_is_not_entered(make_sim, field, robot, lateral_mm, placed):
    """On the real SimTwo (round 1, legs through a grid point) the robot began a place 19 mm off the slot's normal
    and turned 4 deg, its estimate right: it went in, the part met a rib and fell beside the slot. The place gate
    (``dock.place_gate``) backs out along the normal with the part still held and reports ``off_line``; a few
    millimetres off, it places."""
    sim = make_sim(round_no=1, parts="XBXX")
    run = Run(sim, field, robot)
    fp, fc = robot_footprint(robot), carrying_footprint(robot, field.part)
    d = dock_distance(robot, field.part)
    src, dst = field.slot("incoming", 2), field.slot("outgoing", 3)
    pl = PathPlanner(FieldObstacles(field, []))
    sim.set_pose(*pl.approach_pose(src, d, fp))
    o = run.dock(run.docker.start_pick, src, math.hypot(*(a - b for a, b in zip(pl.approach_pose(src, d, fc)[:2],
                                                                                 src.xy))))
    assert o.done and sim.held == 2
    u, n = _slot_axes(dst.facing)
    ap = pl.approach_pose(dst, d, fc)
    lat = lateral_mm / 1000 - run.docker.held_offset  # the part's centre this far to the left of the slot's
    run.goto((ap[0] + lat * n[0], ap[1] + lat * n[1], ap[2]), fc, [])
    assert sim.held == 2
    start_along = (sim.pose[0] - dst.xy[0]) * u[0] + (sim.pose[1] - dst.xy[1]) * u[1]
    retreat = math.hypot(*(a - b for a, b in zip(pl.approach_pose(dst, d, fp)[:2], dst.xy)))
    nearest = math.inf  # m: the part's centre's least distance from the slot's centre along the normal
    run.docker.start_place(dst, sim.pose, retreat)
    for _ in range(1000):
        o = run.docker.step(sim.pose, run.contact)
        run.cycle(o.v, o.w, o.magnet)
        px, py, _ = sim.part_pose(2)
        nearest = min(nearest, (px - dst.xy[0]) * u[0] + (py - dst.xy[1]) * u[1])
        if o.done or o.failed:
            break
    if placed:
        assert o.done and not o.failed and sim.held is None
        px, py, _ = sim.part_pose(2)
        assert math.hypot(px - dst.xy[0], py - dst.xy[1]) < 0.012
        return
    assert o.failed == "off_line" and o.magnet and sim.held == 2  # the part still on the magnet
    # it never went in: the part's centre stayed outside the ribs (3.5 cm out) plus its half depth
    assert nearest > 0.035 + field.part.depth / 2 - 0.005, nearest
    end_along = (sim.pose[0] - dst.xy[0]) * u[0] + (sim.pose[1] - dst.xy[1]) * u[1]
    assert end_along == pytest.approx(start_along, abs=0.01)  # back where it started: room to plan again



@pytest.mark.parametrize("lateral_mm,failed", [(30, "off_line"), (-30, "off_line"), (4, "no_contact")])
def test_a_pick_whose_bumper_would_meet_a_rib_is_not_driven_on(make_sim, field, robot, lateral_mm, failed):
    """On the stand-in (whole stack, round 3) a pick's approach at machine A met no part by the dock pose (the part
    deeper in its slot than the map says) and drove on 19 mm off the slot's normal: the contact switch's bumper went
    in between the ribs and touched one. The pick gate (``dock.pick_gate``) looks once, 6 mm before the dock pose:
    that far off, the robot goes no farther, backs out with the magnet off and reports ``off_line`` (the caller tries
    again from a fresh approach); a few millimetres off, it drives on (here to an empty slot: ``no_contact``)."""
    sim = make_sim(round_no=1, parts="BXXX")  # incoming slot 3 is empty: no contact stops the approach
    run = Run(sim, field, robot)
    fp = robot_footprint(robot)
    d = dock_distance(robot, field.part)
    slot = field.slot("incoming", 3)
    u, n = _slot_axes(slot.facing)
    ap = PathPlanner(FieldObstacles(field, [])).approach_pose(slot, d, fp)
    lat = lateral_mm / 1000
    sim.set_pose(ap[0] + lat * n[0], ap[1] + lat * n[1], ap[2])
    deepest = math.inf  # base_link's least distance from the slot's centre along its normal
    run.docker.start_pick(slot, sim.pose, math.hypot(ap[0] - slot.xy[0], ap[1] - slot.xy[1]))
    for _ in range(1000):
        o = run.docker.step(sim.pose, run.contact)
        run.cycle(o.v, o.w, o.magnet)
        deepest = min(deepest, (sim.pose[0] - slot.xy[0]) * u[0] + (sim.pose[1] - slot.xy[1]) * u[1])
        if o.done or o.failed:
            break
    assert o.failed == failed and not o.magnet and sim.held is None
    if failed == "off_line":
        assert deepest > d - 0.001, deepest  # never past the dock pose: the bumper stayed out of the ribs
    else:
        assert deepest < d - 0.003, deepest  # on past the dock pose, towards where the part would be


def test_the_offset_held_is_taken_where_the_robot_stands_at_the_grip_not_over_its_last_turn():
    """The pick's last samples (base_link's offset, the centre line's at the slot's centre, heading): the robot
    turned 77 -> 90 deg into the slot in its last 0.24 s (the stand-in, issue 20's conditions, round 2 seed 110,
    the estimates). The part stays between the ribs while the robot squares up; the magnet takes it at the grip,
    where the centre line crosses it then: -9 mm. The mean over the turn took -17 mm, beyond the place gate's
    15 mm, and every place after was stopped by it."""
    from robotatfactory.agent.docking import _held_offset

    headings = (79.8, 83.0, 86.0, 88.4, 90.2, 90.0)
    along = (0.124, 0.121, 0.118, 0.114, 0.112, 0.113)
    samples = [(-0.0095, -0.0095 + a * math.tan(math.radians(h - 90)), math.radians(h))
               for h, a in zip(headings, along)]
    old = sum(c for _, c, _ in samples) / len(samples)
    assert old < -0.015  # what the mean took
    assert _held_offset(samples) == pytest.approx((samples[-2][1] + samples[-1][1]) / 2)
    assert _held_offset(samples) == pytest.approx(-0.0095, abs=0.0005)
    still = [(-0.004, -0.012, 0.3)] * 6  # standing turned at the grip: every sample counts, the crossing's
    assert _held_offset(still) == pytest.approx(-0.012)


@pytest.mark.parametrize("held_mm,offset_mm,gated", [(5, 0, False), (5, 21, True), (20, 0, False), (20, 26, False),
                                                     (20, -6, True), (-20, 0, False), (-20, 6, True)])
def test_the_place_gate_lets_a_part_held_off_centre_start_from_the_normal(field, robot, held_mm, offset_mm, gated):
    """A leg ends on the slot's normal: a part held more than the gate (15 mm) off the magnet's centre line starts
    that far off the slot's centre line, and the docker steers it across. The gate then stops only a place whose
    part is more than 5 mm beyond that offset off the line (before: every place, for ever: round 2 seed 110 went
    at its slots 869 times from 34 to 190 s)."""
    limits = DriveLimits.from_robot(robot)
    docker = Docker(limits, robot.control_period, robot.electromagnet["x"], field.part)
    dst = field.slot("outgoing", 3)
    u, n = _slot_axes(dst.facing)
    d = 0.2  # base_link this far out along the normal: the part well outside the ribs
    docker.held_offset = held_mm / 1000
    pose = (dst.xy[0] + d * u[0] + offset_mm / 1000 * n[0], dst.xy[1] + d * u[1] + offset_mm / 1000 * n[1],
            dst.facing + math.pi)
    docker.start_place(dst, pose, 0.2)
    assert docker.settings.place_gate == pytest.approx(0.015)
    o = docker.step(pose, True)  # the part on the magnet: the contact switch pressed
    assert (docker.phase == "back") is gated  # gated: it backs out at once
    if not gated:
        assert docker.phase == "approach" and not o.failed
        return
    x, y, th = pose
    for _ in range(500):  # the robot doing what it is told: back along the normal, then the report
        x, y = x + o.v * math.cos(th) * docker.dt, y + o.v * math.sin(th) * docker.dt
        th += o.w * docker.dt
        o = docker.step((x, y, th), True)
        if o.done or o.failed:
            break
    assert o.failed == "off_line" and o.magnet  # the part still held: the place is planned again
    assert (x - dst.xy[0]) * u[0] + (y - dst.xy[1]) * u[1] >= d - 0.005  # back to where the leg ended
