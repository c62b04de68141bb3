"""RoundAgent's choice of a carried part's destination: the free slot its leg reaches soonest (a kinematic run
of the follower on each planned leg), outgoing slots kept for the parts still to come from machine B."""
import math

import pytest

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.planner import PathPlanner
from robotatfactory.agent.settings import agent_settings
from robotatfactory.agent.state import FactoryState, SlotRef
from robotatfactory.agent.tasks import Move
from robotatfactory.competition import PartType

B = PartType.BLUE


def carrying_agent(field, robot, state, source, **kw):
    """An agent that has just backed out of ``source`` with its blue part (the carrying approach pose)."""
    agent = RoundAgent(field, robot, agent_settings({"tasks": kw}))
    agent.state = state
    agent.carrying = B
    agent.task = Move(B, source, agent.policy.destinations(state, B, source)[0])  # as the policy planned it
    agent.target = agent.task.target
    agent.mode = "pick"
    slot = field.slot(source.zone, source.number)
    pl = PathPlanner(agent._obstacles(exclude=source), margin=agent.settings.carry.margin)
    pose = pl.approach_pose(slot, agent.legs.d_dock, agent.legs.fp_carry)
    return agent, pose


def test_the_destination_its_leg_reaches_soonest(field, robot):
    src = SlotRef("machine_B", 2)
    state = FactoryState.from_letters("XXXX", machine_B="XXXX")  # the part is on the magnet, nothing else
    agent, pose = carrying_agent(field, robot, state, src)
    dest = agent.policy.destinations(state, B, src)
    legs, obstacles = agent.legs, agent._obstacles()
    times = {d: legs.leg_time(legs.plan(obstacles, pose, d, True, "place"), pose, True) for d in dest}
    agent._go_fastest("to_place", pose, dest)
    assert agent.mode == "to_place" and agent.target == min(times, key=times.get)
    # from machine B's output 2: outgoing 3 or 4, straight down; outgoing 1 is the farthest
    assert agent.target in (SlotRef("outgoing", 3), SlotRef("outgoing", 4))
    assert times[SlotRef("outgoing", 1)] > times[agent.target] + 1.0
    # the earlier choice: the nearest to the part's source
    old, pose = carrying_agent(field, robot, state, src, choose_by_time=False)
    old._go_fastest("to_place", pose, dest)
    assert old.target == dest[0] == SlotRef("outgoing", 2)


@pytest.mark.parametrize("pending,kept", [("GXXX", 1), ("GGXX", 2), ("XXXX", 0)])
def test_outgoing_slots_are_kept_for_the_parts_from_machine_b(field, robot, pending, kept):
    src = SlotRef("incoming", 4)
    state = FactoryState.from_letters(pending)
    agent, pose = carrying_agent(field, robot, state, src)
    dest = agent.policy.destinations(state, B, src)
    keep = agent.policy.reserved_outgoing(state, src)
    assert len(keep) == kept
    agent._go_fastest("to_place", pose, dest)
    assert agent.mode == "to_place" and agent.target not in keep
    if not kept:  # nothing to keep: the leg reached soonest, as without the rule
        free, _ = carrying_agent(field, robot, state, src, reserve_outgoing=False)
        free._go_fastest("to_place", pose, dest)
        assert agent.target == free.target


def _pick_and_carry_time(agent, pose, m):
    """The test's own sum for a move: the pick leg from ``pose``, then the carrying leg from the slot's carrying
    approach pose (where the robot backs out to) to the move's target, both the planner's legs (a choice is timed
    by those; ``legs.via_grid`` then only makes the chosen pick leg faster)."""
    legs = agent.legs
    t_pick = legs.leg_time(legs.plan(agent._obstacles(), pose, m.source, False, "pick", via=False), pose, False)
    after = agent.state.with_slot(m.source, None)
    obstacles = legs.obstacles(after)
    start = legs.path_planner(obstacles, True).approach_pose(agent.field.slot(m.source.zone, m.source.number),
                                                             legs.d_dock, legs.footprint(True))
    return t_pick + legs.leg_time(legs.plan(obstacles, start, m.target, True, "place", via=False), start, True)


@pytest.mark.parametrize("via_grid", [0.0, 0.05])
def test_the_next_part_is_the_one_picked_and_carried_soonest(field, robot, via_grid):
    """``tasks.pick_by_time`` (which applies with ``tasks.plan_order`` off) takes the part picked and carried
    soonest."""
    state = FactoryState.from_letters("BBBB")
    sp = field.start_pose
    pose = (sp.x, sp.y, sp.theta)
    chosen = {}
    for by_time in (True, False):
        agent = RoundAgent(field, robot, agent_settings({"tasks": {"pick_by_time": by_time, "plan_order": False},
                                                         "legs": {"via_grid": via_grid}}))
        agent.on_state(state, 0.0)
        agent._decide(pose)
        assert agent.mode == "to_pick" and agent.target == agent.task.source
        chosen[by_time] = agent
    agent = chosen[True]
    tied = agent.policy.tied(state)
    assert len(tied) == 4
    times = {m.source: _pick_and_carry_time(agent, pose, m) for m in tied}
    assert agent.target == min(times, key=times.get)
    # the earlier choice, the nearest part (incoming 1 from the start), takes longer picked and carried
    nearest = chosen[False].target
    assert nearest == SlotRef("incoming", 1) != agent.target
    assert times[nearest] > times[agent.target]
    # the pick leg driven is the chosen one's, through a grid point where that is faster (legs.via_grid)
    legs, obstacles = agent.legs, agent._obstacles()
    plain = legs.plan(obstacles, pose, agent.target, False, "pick", via=False)
    t_plain = legs.leg_time(plain, pose, False)
    leg, t_leg = legs.faster(obstacles, pose, plain, False, "pick", t_plain)
    assert [tuple(p) for p in agent.path.points] == [tuple(p) for p in leg.path.points]
    if not via_grid:
        assert leg is plain


def test_the_part_picked_soonest_is_reached_through_a_grid_point_where_that_is_faster(field, robot):
    """From across the field (0.6, 0, facing +y) the part chosen by time is reached through a grid point
    (``legs.via_grid``, the default): the leg the robot drives is the faster one, by more than half a second."""
    pose = (0.6, 0.0, math.pi / 2)
    agent = RoundAgent(field, robot, agent_settings({"tasks": {"pick_by_time": True, "plan_order": False}}))
    assert agent.settings.legs.via_grid > 0
    agent.on_state(FactoryState.from_letters("BBBB"), 0.0)
    agent._decide(pose)
    assert agent.mode == "to_pick"
    times = {m.source: _pick_and_carry_time(agent, pose, m) for m in agent.policy.tied(agent.state)}
    assert agent.target == min(times, key=times.get)
    legs, obstacles = agent.legs, agent._obstacles()
    plain = legs.plan(obstacles, pose, agent.target, False, "pick", via=False)
    t_plain = legs.leg_time(plain, pose, False)
    leg, t_leg = legs.faster(obstacles, pose, plain, False, "pick", t_plain)
    assert t_leg < t_plain - 0.5
    driven = [tuple(p) for p in agent.path.points]
    assert driven == [tuple(p) for p in leg.path.points] != [tuple(p) for p in plain.path.points]
    assert legs.leg_time(leg, pose, False) == pytest.approx(t_leg)


def test_a_picked_parts_destination_is_chosen_while_it_backs_out(monkeypatch):
    """``tasks.choose_ahead``: the choice of a picked part's destination (a leg planned and timed to each free
    one: 0.85 s in round 1's longest cycle) runs on a thread while the robot grips and backs out, from where the
    back-out ends, and is taken there: in real time the robot no longer stands with its part for it. Bare round
    1: every choice after a pick with two or more destinations ran on that thread (none with the option off),
    and the round goes as it does with the choice made after the back-out: the same parts to the same slots."""
    import threading

    from robotatfactory.experiments.competition import play_round

    fastest = RoundAgent._fastest
    runs = {}
    for ahead in (True, False):
        where = []

        def recorded(self, *args, _where=where, **kw):
            _where.append(threading.current_thread().name)
            return fastest(self, *args, **kw)

        monkeypatch.setattr(RoundAgent, "_fastest", recorded)
        r = play_round(1, 100, record_path=True, agent={"tasks": {"choose_ahead": ahead}})
        assert r["points"] == r["max_points"] and r["collision_checks_hit"] == 0
        if ahead:
            assert r["choices_ahead"] >= 3 and set(where) == {"raf-ahead"} and len(where) == r["choices_ahead"]
            # the back-out ends where the leg was planned from (the pose is the truth): that leg is driven
            assert r["legs_ahead"] == r["choices_ahead"]
        else:
            assert r["choices_ahead"] == r["legs_ahead"] == 0 and where and "raf-ahead" not in where
        runs[ahead] = ([text for _t, text, *_ in r["events"] if text.startswith(("placed", "picked"))],
                       r["last_score_s"])
    assert runs[True][0] == runs[False][0]  # the same parts to the same slots, in the same order
    assert abs(runs[True][1] - runs[False][1]) < 0.5, runs


def test_a_leg_chosen_ahead_is_planned_again_where_the_back_out_ends_away_from_its_start(monkeypatch):
    """A destination chosen while backing out holds within ``AHEAD_POSE`` (3 cm) of where the back-out was to
    end, but its leg, planned from there, is driven only within ``AHEAD_LEG_POSE`` (1 cm): the choice made from
    2 cm beside the back-out's end is taken, and the leg to it planned again from where the robot stands."""
    from robotatfactory.agent import behaviour
    from robotatfactory.agent.docking import Docker
    from robotatfactory.experiments.competition import play_round

    assert behaviour.AHEAD_LEG_POSE[0] < 0.02 <= behaviour.AHEAD_POSE[0]
    retreat = Docker.retreat_pose

    def beside(self):
        x, y, th = retreat(self)
        return x - 0.02 * math.sin(th), y + 0.02 * math.cos(th), th

    monkeypatch.setattr(Docker, "retreat_pose", beside)
    r = play_round(1, 100)
    assert r["points"] == r["max_points"] and r["collision_checks_hit"] == 0
    assert r["choices_ahead"] >= 3 and r["legs_ahead"] == 0


def test_once_every_destination_failed_the_least_failed_are_tried(field, robot):
    """A carried part whose every destination has failed ``give_up_after`` - 1 times is still placed somewhere,
    but the tries go round the slots that failed least instead of repeating the nearest one."""
    src = SlotRef("machine_B", 2)
    state = FactoryState.from_letters("XXXX", machine_B="XXXX")
    agent, pose = carrying_agent(field, robot, state, src)
    dest = agent.policy.destinations(state, B, src)
    n = agent.settings.tasks.give_up_after
    assert len(dest) >= 3 and n >= 2
    agent.place_failed = {dest[0]: n - 1}
    assert agent._usable(dest) == dest[1:]  # below the limit: the others
    agent.place_failed = {d: n - 1 for d in dest}
    assert agent._usable(dest) == dest  # all failed alike: all
    agent.place_failed[dest[0]] = n + 5
    agent.place_failed[dest[1]] = n
    assert agent._usable(dest) == dest[2:]  # the least failed
    agent._go_fastest("to_place", pose, agent._usable(dest))
    assert agent.mode == "to_place" and agent.target in dest[2:]
