"""A part dropped on the floor is found and picked up again (issue 20 item 5), without ROS or a simulator: the
finder (agent/refind.py) on synthetic LIDAR sweeps, and the round's behaviour on a kinematic robot (the
commands integrated exactly) that carries a part on its magnet, drops it where the test says, sees it with a
ray-cast LIDAR and presses its contact switch on it. tests/test_agent_drop_sim.py does it on the stand-in."""
import math

import numpy as np
import pytest

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.footprint import PLATE_THICKNESS, robot_footprint, wrap
from robotatfactory.agent.obstacles import FieldObstacles
from robotatfactory.agent.refind import FoundPart, Scan, find_part, fit_box, lost_spot
from robotatfactory.agent.settings import agent_settings
from robotatfactory.agent.state import FactoryState, SlotRef
from robotatfactory.competition.parts import PartType

from test_agent_recovery import KinRobot


def _ray_hits(origin, angles, polygons) -> np.ndarray:
    """Distance along each ray (angles, field frame) from ``origin`` to the nearest edge of ``polygons``
    (-1: none)."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)  # n x 2
    best = np.full(len(angles), np.inf)
    for poly in polygons:
        a = np.asarray(poly, dtype=float)
        b = np.roll(a, -1, axis=0)
        e = b - a  # k x 2
        w = a - np.asarray(origin)  # k x 2
        den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # n x k
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
            u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / den
        ok = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
        best = np.minimum(best, np.where(ok, t, np.inf).min(axis=1))
    return np.where(np.isfinite(best), best, -1.0)


def _box(x, y, yaw, x0, x1, hy):
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[x0, -hy], [x1, -hy], [x1, hy], [x0, hy]])
    return local @ np.array([[c, s], [-s, c]]) + (x, y)


def part_body(part, x, y, facing):
    """The part's body as the LIDAR sees it (above the plate): depth x width around its centre."""
    return _box(x, y, facing, -part.depth / 2, part.depth / 2, part.width / 2)


def synthetic_scan(field, robot, pose, t, extra=(), noise=0.0, rng=None) -> Scan:
    """A sweep of the robot file's LIDAR at ``pose`` against the field's walls and ribs and ``extra`` polygons;
    every ray measured at ``t`` (a robot standing still)."""
    L = robot.lidar
    n = int(L.rays)
    fov = math.radians(L.fov_deg)
    a = -fov / 2 + np.arange(n) * fov / (n - 1)
    x, y, th = pose
    ox, oy = x + math.cos(th) * L.xyz[0] - math.sin(th) * L.xyz[1], y + math.sin(th) * L.xyz[0] + math.cos(th) * L.xyz[1]
    r = _ray_hits((ox, oy), th + a, [b.footprint() for b in field.boxes] + list(extra))
    if noise:
        r = np.where(r > 0, r + rng.normal(0.0, noise, n), r)
    r = np.where(r > L.range_max, -1.0, r)
    return Scan.from_lidar(L, t, r)


class FloorBot(KinRobot):
    """KinRobot with a part that can lie on the floor (``floor``: (x, y, facing) or None): the contact switch's
    1 cm beam (robot file ``contact``) presses on any of its faces, the magnet holds it when that face is the
    plate and the robot faces it within 45 degrees, the robot cannot drive into it, and the LIDAR sees it."""

    def __init__(self, field, robot, letters="XBXX"):
        super().__init__(field, robot, letters)
        self.robot = robot
        self.floor = None
        self.part = field.part
        self.fp = robot_footprint(robot)

    def drop(self, x, y, facing, spin: float = 0.0) -> None:
        """The held part falls off and comes to rest at (x, y) with its plate towards ``facing``; ``spin`` (rad):
        the robot turns that much on the spot meanwhile (a part that falls straight down stays behind only when
        the robot turns away from it: turns on the spot are where SimTwo's magnet loses parts)."""
        self.held = False
        self.floor = (x, y, facing)
        self.pose = (self.pose[0], self.pose[1], wrap(self.pose[2] + spin))

    def _part_poly(self):
        x, y, f = self.floor
        return _box(x, y, f, -self.part.depth / 2, self.part.depth / 2 + PLATE_THICKNESS, self.part.width / 2)

    def _beam(self, pose=None):
        """(distance along the contact switch's beam to the part, whether it hits the plate face) or None."""
        if self.floor is None:
            return None
        x, y, th = pose or self.pose
        c = self.robot.contact
        ox = x + math.cos(th) * c["xyz"][0] - math.sin(th) * c["xyz"][1]
        oy = y + math.sin(th) * c["xyz"][0] + math.cos(th) * c["xyz"][1]
        d = _ray_hits((ox - 0.005 * math.cos(th), oy - 0.005 * math.sin(th)), np.array([th]), [self._part_poly()])[0]
        if d < 0:
            return None
        px, py, f = self.floor
        hx, hy = ox + (d - 0.005) * math.cos(th), oy + (d - 0.005) * math.sin(th)
        local_x = (hx - px) * math.cos(f) + (hy - py) * math.sin(f)
        return d - 0.005, local_x > self.part.depth / 2 + PLATE_THICKNESS / 2 - 1e-4

    def contact(self) -> bool:
        if super().contact():
            return True
        b = self._beam()
        return b is not None and b[0] <= float(self.robot.contact["beam"])

    def move(self, cmd) -> None:
        b = self._beam()
        was = self.held
        if self.floor is not None:  # on the floor: the magnet holds it only by its plate, faced
            self.held = bool(cmd.magnet and self.can_hold and b is not None and b[0] <= 0.01 and b[1] and
                             abs(wrap(self.pose[2] - self.floor[2] - math.pi)) < math.radians(45))
            if self.held:
                self.floor = None
        else:  # in a slot, or on the magnet
            self.held = bool(cmd.magnet and self.can_hold and (self.held or KinRobot.contact(self)))
        if self.held and not was and b is None:  # taken from a slot: the server no longer lists it there
            for n, p in enumerate(self.state.zone("incoming"), start=1):
                s = self.field.slot("incoming", n)
                if p is not None and math.hypot(self.pose[0] - s.xy[0], self.pose[1] - s.xy[1]) < 0.2:
                    self.state = self.state.with_slot(SlotRef("incoming", n), None)
        x, y, th = self.pose
        nx, ny = x + cmd.v * math.cos(th) * self.dt, y + cmd.v * math.sin(th) * self.dt
        pose = (nx, ny, wrap(th + cmd.w * self.dt))
        if self.floor is not None:  # the robot's outline cannot enter the part
            from robotatfactory.agent.obstacles import polygons_overlap

            if any(polygons_overlap(p, self._part_poly()) for p in self.fp.polygons(*pose)):
                pose = self.pose
        self.pose = pose
        self.t += self.dt

    def scan(self) -> Scan:
        extra = [part_body(self.part, *self.floor)] if self.floor is not None else []
        return synthetic_scan(self.field, self.robot, self.pose, self.t, extra)


def run(agent, bot, until, limit=60.0, scans=True):
    """Cycle until ``until(agent)`` or ``limit`` s; a LIDAR sweep every 0.2 s (``scans``)."""
    k = 0
    while bot.t < limit:
        if agent.wants_state:
            agent.on_state(bot.state, bot.t)
        if scans and k % 5 == 0:
            agent.on_scan(bot.scan())
        c = agent.step(bot.t, bot.pose, bot.contact())
        bot.move(c)
        k += 1
        if until(agent):
            return True
    return False


def carry_then_drop(field, robot, settings=None, scans=True):
    """The agent picks the blue part of incoming 2 and sets off; returns the agent, the robot and the spot where
    the part was when it fell (lost_spot of the pose then)."""
    agent = RoundAgent(field, robot, agent_settings(settings or {}))
    bot = FloorBot(field, robot)
    assert run(agent, bot, lambda a: a.mode == "to_place" and abs(a._v) > 0.15, scans=scans)
    assert bot.held and agent.counters.picks == 1
    return agent, bot, lost_spot(bot.pose, robot.electromagnet["x"], field.part)


def events_after(agent, t0=0.0):
    return [text for t, text in agent.events if t >= t0]


# ------------------------------------------------------------------------------------------ the finder
@pytest.mark.parametrize("bearing,facing", [(0.0, 0.3), (0.5, 2.0), (-0.6, -1.2), (3.0, 0.9), (0.2, math.pi / 2)])
def test_the_part_is_fitted_to_the_lidar_returns_within_millimetres(field, robot, bearing, facing):
    """A part 0.2 m from the LIDAR in several directions and orientations, range noise as the robot file's at
    that distance (2 mm): its centre within 5 mm, its depth axis within 3 degrees, both faces offered."""
    rng = np.random.default_rng(7)
    pose = (0.0, -0.2, 0.4)
    px, py = pose[0] + 0.2 * math.cos(pose[2] + bearing), pose[1] + 0.2 * math.sin(pose[2] + bearing)
    scan = synthetic_scan(field, robot, pose, 0.0, [part_body(field.part, px, py, facing)], noise=0.002, rng=rng)
    near = FoundPart(px + 0.06, py - 0.05, (facing + 0.4,))  # where it fell, roughly
    ob = FieldObstacles(field, [])
    f = find_part(scan, pose, robot.lidar.xyz[:2], near, ob, field.part, robot_footprint(robot), 0.3, 0.02)
    assert f is not None and f.points >= 5
    assert math.hypot(f.x - px, f.y - py) < 0.005
    assert abs(wrap(f.facings[0] - facing)) < math.radians(3)  # the hint's side first
    assert abs(wrap(f.facings[1] - facing - math.pi)) < math.radians(3)


def test_returns_the_map_explains_are_not_a_part(field, robot):
    """Next to a rib nothing is found (the rib is the map's); a part there is."""
    box = field.boxes[0]
    poly = box.footprint()
    c = poly.mean(axis=0)
    pose = (float(c[0]), float(c[1]) - 0.3, math.pi / 2)
    if FieldObstacles(field, []).clearance_at(*pose[:2]) < 0.1:  # (a free spot in front of that rib)
        pose = (float(c[0]), float(c[1]) + 0.3, -math.pi / 2)
    scan = synthetic_scan(field, robot, pose, 0.0)
    near = FoundPart(float(c[0]), float(c[1]), (0.0,))
    ob = FieldObstacles(field, [])
    assert find_part(scan, pose, (0.0, 0.0), near, ob, field.part, robot_footprint(robot), 0.35, 0.02) is None
    # nothing in range at all
    empty = Scan.from_lidar(robot.lidar, 0.0, [-1.0] * robot.lidar.rays)
    assert find_part(empty, pose, (0.0, 0.0), near, ob, field.part, robot_footprint(robot), 0.35, 0.02) is None


def test_a_box_fit_takes_the_size_the_points_allow():
    """One long face seen: the depth axis is across it, the centre behind it; an L of both faces: the corner."""
    depth, width = 0.06, 0.09
    ys = np.linspace(-0.045, 0.045, 15)
    pts = np.column_stack([np.full_like(ys, 0.2 - 0.03), ys])  # the face at x = 0.17 seen from the origin
    cx, cy, axis = fit_box(pts, (0.0, 0.0), depth, width, facing_hint=math.pi)
    assert (cx, cy) == pytest.approx((0.2, 0.0), abs=1e-3) and abs(wrap(2 * axis)) < 1e-6
    xs = np.linspace(0.2 - 0.03, 0.2 + 0.03, 8)
    pts = np.vstack([pts, np.column_stack([xs, np.full_like(xs, -0.045)])])  # and the short face at y = -0.045
    cx, cy, _ = fit_box(pts, (0.0, -0.3), depth, width, facing_hint=0.0)
    assert (cx, cy) == pytest.approx((0.2, 0.0), abs=1e-3)
    assert fit_box(np.array([[0.0, 0.0], [0.3, 0.0], [0.0, 0.3]]), (1.0, 1.0), depth, width, 0.0) is None


# ------------------------------------------------------------------------------------------ the behaviour
def test_a_dropped_part_is_found_with_the_lidar_picked_up_and_carried_on(field, robot):
    agent, bot, spot = carry_then_drop(field, robot)
    t_drop = bot.t
    # it slid 9 cm to the side and turned by 35 degrees before it came to rest
    th = bot.pose[2]
    px, py = spot.x - 0.09 * math.sin(th), spot.y + 0.09 * math.cos(th)
    bot.drop(px, py, wrap(spot.facings[0] + math.radians(35)))
    assert run(agent, bot, lambda a: a.counters.places >= 1 or a.mode == "done", limit=t_drop + 40.0)
    c = agent.counters
    assert (c.parts_lost, c.parts_refound, c.floor_picks, c.floor_pick_failures, c.places) == (1, 1, 1, 0, 1), \
        events_after(agent, t_drop)
    ev = events_after(agent, t_drop)
    order = ["lost the blue part", "looking for it", "LIDAR: found the lost blue part", "docking to pick the lost",
             "picked the lost blue part up from the floor", "docking to place the blue part", "placed the blue part"]
    at = [next(i for i, text in enumerate(ev) if text.startswith(o)) for o in order]
    assert at == sorted(at), ev
    found = next(t for t in ev if t.startswith("LIDAR: found"))
    assert "cm from where it fell" in found
    assert agent.target.zone == "outgoing" and agent.mode in ("decide", "to_pick", "done")


def test_without_a_lidar_it_picks_the_part_up_where_it_fell(field, robot):
    agent, bot, spot = carry_then_drop(field, robot, scans=False)
    t_drop = bot.t
    bot.drop(spot.x, spot.y, spot.facings[0], spin=1.6)  # straight down, the robot turning away
    assert run(agent, bot, lambda a: a.counters.places >= 1, limit=t_drop + 40.0, scans=False)
    c = agent.counters
    assert (c.parts_refound, c.floor_picks, c.floor_pick_failures) == (0, 1, 0)
    assert any(t.startswith("LIDAR: no LIDAR: picking it up where it fell") for t in events_after(agent, t_drop))


def test_the_plate_turned_away_is_picked_from_the_other_side_on_the_next_try(field, robot):
    """The LIDAR cannot see the plate (below its scan plane): the first try faces the side the plate faced when
    the part fell; it turned half round, so the contact closes but the magnet does not hold; the second try
    faces the other side."""
    agent, bot, spot = carry_then_drop(field, robot)
    t_drop = bot.t
    th = bot.pose[2]
    bot.drop(spot.x + 0.03 * math.cos(th), spot.y + 0.03 * math.sin(th), wrap(spot.facings[0] + math.pi), spin=-1.6)
    assert run(agent, bot, lambda a: a.counters.places >= 1, limit=t_drop + 60.0)
    c = agent.counters
    assert (c.floor_pick_failures, c.floor_picks, c.places) == (1, 1, 1), events_after(agent, t_drop)
    assert any("failed: part_lost (try 1 of 3)" in t for t in events_after(agent, t_drop))


def test_a_part_that_cannot_be_picked_up_is_left_on_the_floor_after_the_tries(field, robot):
    agent, bot, spot = carry_then_drop(field, robot, {"recovery": {"refind_tries": 2}})
    t_drop = bot.t
    bot.drop(spot.x, spot.y, spot.facings[0], spin=1.6)
    bot.can_hold = False  # the magnet never holds it
    assert run(agent, bot, lambda a: a.counters.parts_left >= 1, limit=t_drop + 60.0)
    c = agent.counters
    assert (c.floor_pick_failures, c.floor_picks, c.parts_left) == (2, 0, 1)
    assert agent.lost is None and len(agent.floor_parts) == 1
    assert math.hypot(agent.floor_parts[0].x - spot.x, agent.floor_parts[0].y - spot.y) < 0.01
    assert any(t.startswith("left the lost blue part on the floor") for t in events_after(agent, t_drop))
    # the round goes on without it (the server lists no other part: done); the part is an obstacle from now on
    # for legs with a part on the magnet (the empty robot may push it aside)
    assert run(agent, bot, lambda a: a.mode == "done", limit=bot.t + 5.0)
    assert agent._obstacles().clearance_at(spot.x, spot.y) > 0.02
    agent.carrying = PartType.BLUE
    assert agent._obstacles().clearance_at(spot.x, spot.y) == 0.0


def test_a_part_that_landed_in_a_slot_is_left_to_the_next_decision(field, robot):
    """The server lists the lost part in a slot near where it fell: no floor pick, the agent decides again."""
    agent, bot, spot = carry_then_drop(field, robot, scans=False)
    t_drop = bot.t
    # the part falls: the server (asked after the loss) lists it in the empty slot nearest the spot (just
    # after the pick from incoming 2, its neighbours are within reach)
    slots = [SlotRef(z, n) for z in ("incoming", "outgoing") for n in range(1, 5) if bot.state.at(SlotRef(z, n)) is None]
    ref = min(slots, key=lambda r: math.hypot(field.slot(r.zone, r.number).xy[0] - spot.x,
                                              field.slot(r.zone, r.number).xy[1] - spot.y))
    s = field.slot(ref.zone, ref.number)
    assert math.hypot(s.xy[0] - spot.x, s.xy[1] - spot.y) < agent.settings.recovery.refind_radius
    bot.held = False
    bot.state = bot.state.with_slot(ref, PartType.BLUE)
    zone, n = ref.zone, ref.number
    assert run(agent, bot, lambda a: a.counters.parts_lost and a.lost is None, limit=t_drop + 5.0, scans=False)
    assert agent.counters.floor_picks == 0 and agent.mode != "floor_pick"
    assert any(f"is in {zone} {n}" in t for t in events_after(agent, t_drop)), events_after(agent, t_drop)


def test_a_part_let_go_while_backing_out_of_a_pick_is_found_on_the_floor(field, robot):
    """Held at the slot, then let go while backing out (the pick fails: part_lost) and out of its slot, which the
    server no longer lists: it lies on the floor in front of the robot; looked for and picked up from there."""
    agent = RoundAgent(field, robot)
    bot = FloorBot(field, robot)
    assert run(agent, bot, lambda a: a.mode == "pick" and a.docker.phase == "back" and bot.held)
    t0 = bot.t
    s = field.slot("incoming", 2)

    def out_of_slot(a):  # 4 cm out of it (the server takes it as gone)
        spot = lost_spot(bot.pose, robot.electromagnet["x"], field.part)
        return math.hypot(spot.x - s.xy[0], spot.y - s.xy[1]) > 0.04

    assert run(agent, bot, out_of_slot, limit=t0 + 2.0) and agent.mode == "pick"
    spot = lost_spot(bot.pose, robot.electromagnet["x"], field.part)
    bot.drop(spot.x, spot.y, wrap(s.facing + 0.2))  # it stays where it is (caught on a rib) as the robot backs on
    bot.can_hold = False
    assert run(agent, bot, lambda a: a.mode == "search", limit=t0 + 5.0)
    bot.can_hold = True
    assert run(agent, bot, lambda a: a.counters.places >= 1, limit=t0 + 40.0)
    c = agent.counters
    assert (c.pick_failures, c.parts_lost, c.parts_refound, c.floor_picks, c.places) == (1, 1, 1, 1, 1)
    ev = events_after(agent, t0)
    assert any(t.startswith("pick at incoming 2 failed: part_lost") for t in ev), ev
    assert any(t.startswith("lost the blue part picking it at incoming 2: the server no longer lists it") for t in ev)
    assert any(t.startswith("picked the lost blue part up from the floor") for t in ev)


def test_a_part_let_go_at_the_pick_that_stays_in_its_slot_is_picked_there_again(field, robot):
    """part_lost but the server still lists it in its slot: the usual retry, no floor search."""
    agent = RoundAgent(field, robot)
    bot = FloorBot(field, robot)
    assert run(agent, bot, lambda a: a.mode == "pick" and a.docker.phase == "back" and bot.held)
    bot.held, bot.can_hold = False, False  # it stays in the slot
    bot.state = bot.state.with_slot(SlotRef("incoming", 2), PartType.BLUE)
    assert run(agent, bot, lambda a: a.counters.pick_failures >= 1 and a.mode == "to_pick", limit=bot.t + 5.0)
    assert agent.counters.parts_lost == 0 and agent.lost is None and str(agent.target) == "incoming 2"


def test_a_part_the_server_does_not_list_after_its_place_is_found_and_placed_again(field, robot):
    """A place that went wrong (the part met the slot's wall and ended out of it): the robot placed and backed out
    as usual, but the first state after the place does not list the part there. The agent looks for it near the
    slot, picks it up from the floor and places it again; the second place is listed, and nothing more happens.
    With ``recovery.check_place`` off the agent goes on as if it had scored."""
    for check in (True, False):
        agent = RoundAgent(field, robot, agent_settings({"recovery": {"check_place": check}}))
        bot = FloorBot(field, robot)
        assert run(agent, bot, lambda a: a.mode == "place" and a.docker.phase == "back" and not a.magnet)
        t0 = bot.t
        dest = agent.target
        # it came to rest 4 cm to the side of the slot's centre and 1 cm out, turned by 0.3 rad (caught on a rib)
        s = field.slot(dest.zone, dest.number)
        side = (math.sin(s.facing), -math.cos(s.facing))
        bot.floor = (s.xy[0] + 0.04 * side[0] + 0.01 * math.cos(s.facing),
                     s.xy[1] + 0.04 * side[1] + 0.01 * math.sin(s.facing), wrap(s.facing + 0.3))
        if not check:
            assert run(agent, bot, lambda a: a.counters.places >= 1 and a.mode != "place", limit=t0 + 5.0)
            assert run(agent, bot, lambda a: a.mode == "done", limit=t0 + 10.0)
            assert agent.counters.parts_lost == 0 and not any("after the place" in t for t in events_after(agent, t0))
            continue
        assert run(agent, bot, lambda a: a.mode == "search", limit=t0 + 5.0)
        assert agent.counters.parts_lost == 1
        assert any(t.startswith(f"the blue part is not in {dest} after the place: the server does not list it")
                   for t in events_after(agent, t0)), events_after(agent, t0)

        listed = []

        def listed_after_second_place(a):  # the second place goes right: the server lists it where it went
            if a.counters.places >= 2 and not listed:
                listed.append(a.target)
                bot.state = bot.state.with_slot(a.target, PartType.BLUE)
            return a.mode == "done"

        assert run(agent, bot, listed_after_second_place, limit=t0 + 60.0), events_after(agent, t0)
        c = agent.counters
        assert (c.parts_lost, c.floor_picks, c.places) == (1, 1, 2) and c.parts_refound >= 1, events_after(agent, t0)
        assert bot.floor is None and agent.lost is None


def test_a_state_polled_in_the_cycle_of_a_decision_is_not_one_after_it(field, robot):
    """The caller polls the server, then steps the agent, in one cycle: a state polled in the cycle a place ended
    in was taken before it. The agent asks for (and waits for) one polled later: the first state after a place
    decides whether the part is in its slot (a state from before it would always say so, the agent having
    entered its own expectation)."""
    agent = RoundAgent(field, robot)
    st = FactoryState.from_letters("XBXX")
    agent.on_state(st, 5.0)
    agent.t, agent.mode, agent.need_state_after = 5.0, "decide", 5.0  # decided on in the cycle at 5.0 s
    assert agent.wants_state
    agent.step(5.0, (0.0, -0.3, 0.0), False)
    assert agent.mode == "decide" and agent.state_time == 5.0  # waits for a later state
    agent.on_state(st, 5.04)
    assert not agent.wants_state
