"""Never a stuck loop when there is no path (issue 11): a robot standing too close to something for its
outline (pushed into a corner: on the whole stack, round 2 seed 3, it asked for a path every 0.56 s for 135 s)
first drives to the nearest clear point, and a target that has no path several times running is given up.
The robot is the kinematic unicycle of test_agent_recovery."""
import math

import numpy as np

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.planner import PathPlanner
from test_agent_recovery import KinRobot, run


def _cornered_pose(field, robot):
    """A pose whose nearest point clear for the empty outline is 11-20 cm away, base_link itself 2 cm or more
    from anything: farther than the planner joins a start to its grid (10 cm)."""
    from robotatfactory.agent.state import FactoryState

    agent = RoundAgent(field, robot)
    agent.state = FactoryState.from_letters("XBXX")
    obs = agent._obstacles()
    pl = PathPlanner(obs, margin=0.01)
    for x in np.arange(-0.8, 0.8, 0.01):
        for y in np.arange(-0.55, 0.55, 0.01):
            if obs.clearance_at(x, y) < 0.02:
                continue
            p = pl.escape_point((x, y), agent.legs.fp_empty)
            if p is not None and 0.11 < math.hypot(p[0] - x, p[1] - y) < 0.2:
                return (float(x), float(y), math.atan2(p[1] - y, p[0] - x) + math.pi)  # facing away from it
    raise AssertionError("no cornered spot on this field")


def _carrying_poses_beside_clear(agent):
    """(pose, nearest clear point) for poses whose nearest point clear for the carrying outline lies beside
    them, 5 cm or more away; the pose heading across the way to it, its outline touching nothing."""
    obs = agent._obstacles()
    pl, fp = agent.legs.path_planner(obs, True), agent.legs.fp_carry
    out = []
    for x in np.arange(-0.6, 0.6, 0.03):
        for y in np.arange(-0.35, 0.35, 0.03):
            if pl.is_free((x, y), fp) or obs.clearance_at(x, y) < 0.03:
                continue
            near = pl.escape_point((x, y), fp)
            if near is None or math.hypot(near[0] - x, near[1] - y) < 0.05:
                continue
            h = math.atan2(near[1] - y, near[0] - x) + math.pi / 2
            if not obs.collides(fp, (x, y, h)):
                out.append(((float(x), float(y), h), near))
    return out


def test_a_cornered_robot_drives_clear_then_goes_on(field, robot):
    agent = RoundAgent(field, robot)
    bot = KinRobot(field, robot)
    bot.pose = _cornered_pose(field, robot)
    run(agent, bot, lambda a: a.mode == "pick", limit=40.0)
    assert agent.counters.escapes >= 1, agent.events[:6]
    assert any("driving to" in text for _, text in agent.events)
    assert agent.mode == "pick", agent.events[-5:]  # it got clear, planned and reached the part
    assert agent.counters.no_path <= agent.settings.recovery.escape_tries


def test_a_target_without_a_path_is_given_up_not_asked_for_forever(field, robot):
    agent = RoundAgent(field, robot)
    bot = KinRobot(field, robot)  # one blue part, in incoming 2
    s = field.slot("incoming", 2)
    u = (math.cos(s.facing), math.sin(s.facing))
    # something on the floor in front of the slot, as far as an approach could be, for the whole round
    agent.blocked_spots = [(s.xy[0] + d * u[0] + o * u[1], s.xy[1] + d * u[1] - o * u[0], math.inf)
                           for d in np.arange(0.06, 0.4, 0.04) for o in (-0.03, 0.0, 0.03)]
    run(agent, bot, lambda a: a.mode == "done", limit=60.0)
    assert agent.mode == "done", agent.events[-5:]
    assert any("giving it up" in text for _, text in agent.events)
    assert agent.counters.no_path == agent.settings.tasks.give_up_after and agent.counters.picks == 0



def test_a_cornered_robot_with_a_part_escapes_straight_not_sideways(field, robot):
    """Carrying, the escape drive never turns on the spot, so a clear point beside the robot is one it cannot
    reach (whole stack, round 3: three escapes barely moved it, then it stood still for 170 s). Its escape point
    lies straight ahead or behind where one is clear within 0.3 m: on the heading's line, the outline clear all
    the way at the robot's heading. The empty robot still goes to the nearest clear point."""
    from robotatfactory.agent.state import FactoryState

    agent = RoundAgent(field, robot)
    agent.state = FactoryState.from_letters("XXXX")
    obs = agent._obstacles()
    legs = agent.legs
    pl, fp = legs.path_planner(obs, True), legs.fp_carry
    cases = 0
    for (x, y, h), near in _carrying_poses_beside_clear(agent):
        escape = legs.escape_point(obs, (x, y, h), carrying=True)
        assert escape is not None
        p = escape.xy
        on_line = abs(-(p[0] - x) * math.sin(h) + (p[1] - y) * math.cos(h)) < 1e-9
        assert on_line if escape.straight else p == near
        if not escape.straight:
            continue  # (no straight way out within 0.3 m: the nearest clear point, as before)
        cases += 1
        d = math.hypot(p[0] - x, p[1] - y)
        assert pl.is_free(p, fp) and d <= 0.3 + 1e-9
        sign = 1.0 if (p[0] - x) * math.cos(h) + (p[1] - y) * math.sin(h) > 0 else -1.0
        for s in np.arange(0.01, d, 0.01):
            assert not obs.collides(fp, (x + sign * s * math.cos(h), y + sign * s * math.sin(h), h))
        empty = legs.path_planner(obs, False).escape_point((x, y), legs.fp_empty)
        got = legs.escape_point(obs, (x, y, h), carrying=False)
        assert (got and got.xy) == empty and not (got and got.straight)
    assert cases >= 10


def test_a_cornered_robot_with_a_part_and_no_straight_way_out_turns_on_its_last_escape(field, robot):
    """Carrying, where no straight way out is clear within 0.3 m, the escape point lies beside the robot. The
    drive steers and never turns on the spot, so it cannot end there: on the whole stack (round 3) three such
    escapes barely moved the robot and it stood still for the rest of the round. The last try turns on the spot
    to the point: it ends there, where a leg can be planned from."""
    from robotatfactory.agent.state import FactoryState, SlotRef
    from robotatfactory.competition.rounds import PartType

    agent = RoundAgent(field, robot)
    agent.state = FactoryState.from_letters("XXXX")
    obs = agent._obstacles()
    legs = agent.legs
    poses = [(pose, near) for pose, near in _carrying_poses_beside_clear(agent)  # no straight way out
             if not legs.escape_point(obs, pose, carrying=True).straight]
    assert len(poses) >= 5, "no such poses on this field"
    tries = agent.settings.recovery.escape_tries
    target = SlotRef("outgoing", 1)
    for pose, near in poses:
        agent = RoundAgent(field, robot)
        agent.state = FactoryState.from_letters("XXXX")
        ends = []
        for k in range(tries):
            agent.carrying, agent.target, agent.mode = PartType.BLUE, target, "decide"
            agent._no_leg(pose)
            assert agent.mode == "escape"
            spin = not agent.follower.no_spin
            bot = KinRobot(field, robot)
            bot.pose = pose
            run(agent, bot, lambda a: a.mode != "escape", limit=agent.settings.recovery.escape_time + 1.0)
            ends.append((spin, math.hypot(bot.pose[0] - near[0], bot.pose[1] - near[1]), bot.pose))
        assert [spin for spin, _, _ in ends] == [False] * (tries - 1) + [True], ends
        assert all(d > 0.03 for _, d, _ in ends[:-1]), ends  # steering, it never ends at the point
        assert ends[-1][1] < 0.01, ends
        legs.plan(obs, ends[-1][2], target, True, "place")  # (raises NoPath where it could not plan from)
        agent._no_leg(pose)  # every try spent: no more escapes
        assert agent.mode != "escape"


def test_escapes_that_end_short_of_clear_space_start_again_once_the_target_is_given_up(field, robot):
    """An escape drive ends after ``recovery.escape_time`` or off its path (a pose that jumps), so it may end
    short of clear space. With every try spent, a robot still too close to something asked for a path, gave
    its target up, and asked again, standing still for the rest of the round ("Not done yet" in docs/agent.md).
    Giving a target up starts a new round of escapes: the cornered robot with a part, whose escapes are cut
    short (0.5 s each), gets clear and goes on to its place."""
    from robotatfactory.agent.settings import agent_settings
    from robotatfactory.agent.state import FactoryState, SlotRef
    from robotatfactory.competition.rounds import PartType

    probe = RoundAgent(field, robot)
    probe.state = FactoryState.from_letters("XXXX")
    obs = probe._obstacles()
    poses = [pose for pose, _ in _carrying_poses_beside_clear(probe)
             if not probe.legs.escape_point(obs, pose, carrying=True).straight]
    settings = agent_settings({"recovery": {"escape_time": 0.5}})
    tries = settings.recovery.escape_tries
    again = 0
    for pose in poses:
        agent = RoundAgent(field, robot, settings=settings)
        agent.state = FactoryState.from_letters("XXXX")
        agent.carrying, agent.target, agent.mode = PartType.BLUE, SlotRef("outgoing", 1), "decide"
        bot = KinRobot(field, robot, letters="XXXX")
        bot.pose, bot.held = pose, True
        run(agent, bot, lambda a: a.mode == "to_place", limit=30.0)
        assert agent.mode == "to_place", (pose, agent.counters.escapes, agent.events[-4:])
        if agent.counters.escapes > tries:
            again += 1
            assert any("giving it up" in text for _, text in agent.events)
    assert again >= 1  # (some of these robots needed a second round of escapes)
