"""RoundAgent's choice of a carried part's destination: the free slot its leg reaches soonest (a kinematic run
of the follower on each planned leg), outgoing slots kept for the parts still to come from machine B."""
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
