"""A pick that misses (no contact at the end of the approach) is retried from a fresh approach: the robot backs
out, plans the leg to the slot's approach pose again from where it stands and docks a second time; after
``dock.retries`` misses the task is decided again. The kinematic robot of tests/test_agent_recovery.py, its
contact switch held open for the first approaches."""
import math

from test_agent_recovery import KinRobot, run

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.settings import agent_settings


def _misses(n):
    """A contact switch that stays open until ``n`` pick approaches have failed."""
    def contact(bot, agent):
        return bot.contact() if agent.counters.pick_failures >= n else False
    return contact


def test_a_missed_pick_is_tried_again_from_a_fresh_approach(field, robot):
    agent = RoundAgent(field, robot)
    bot = KinRobot(field, robot)
    modes = []
    run(agent, bot, lambda a: modes.append(a.mode) or a.counters.picks == 1, contact=lambda b: _misses(1)(b, agent))
    assert agent.counters.pick_failures == 1 and agent.counters.picks == 1 and bot.held
    failed = [(t, e) for t, e in agent.events if "failed: no_contact" in e]
    picked = [(t, e) for t, e in agent.events if e.startswith("picked ")]
    assert len(failed) == 1 and len(picked) == 1 and failed[0][0] < picked[0][0]
    slot = failed[0][1].split(" at ")[1].split(" failed")[0]
    assert picked[0][1].endswith(f"from {slot}")  # the same part, the second time
    docked = [t for t, e in agent.events if e.startswith("docking to pick")]
    assert len(docked) == 2  # two approaches
    # between them a new leg to the approach pose: pick -> to_pick -> pick
    seq = [m for i, m in enumerate(modes) if i == 0 or m != modes[i - 1]]
    assert seq.count("pick") == 2 and "to_pick" in seq[seq.index("pick"):]


def test_after_every_retry_missed_the_task_is_decided_again(field, robot):
    agent = RoundAgent(field, robot, agent_settings({"dock": {"retries": 2}}))
    bot = KinRobot(field, robot)
    run(agent, bot, lambda a: a.counters.pick_failures >= 2 and a.mode == "decide", contact=lambda b: False,
        limit=90.0)
    assert agent.counters.pick_failures == 2 and agent.counters.picks == 0
    assert sum(e.startswith("docking to pick") for _, e in agent.events) == 2
    assert agent.failures  # the slot's failures counted (given up after tasks.give_up_after)


def test_a_pick_gated_off_the_line_is_tried_again_from_a_fresh_approach(field, robot):
    """The robot pushed 30 mm sideways as its first pick approach begins (a lost command, a slip: the stand-in's
    round 3 came in 19 mm off) reaches the pick gate's point still off the slot's centre line: it does not drive on
    between the ribs (``off_line``), backs out, plans the leg to the approach pose again and picks."""

    agent = RoundAgent(field, robot)
    bot = KinRobot(field, robot)
    pushed, modes = [], []

    def until(a):
        modes.append(a.mode)
        if a.mode == "pick" and not pushed:
            s = a.field.slot(a.target.zone, a.target.number)
            n = (math.sin(s.facing), -math.cos(s.facing))
            x, y, th = bot.pose
            bot.pose = (x + 0.03 * n[0], y + 0.03 * n[1], th)
            pushed.append(a.t)
        return a.counters.picks == 1

    run(agent, bot, until)
    assert pushed and agent.counters.picks == 1 and bot.held
    failed = [e for _, e in agent.events if "failed: off_line" in e]
    assert len(failed) == 1 and failed[0].startswith("pick at ")
    assert sum(e.startswith("docking to pick") for _, e in agent.events) == 2  # a second, fresh approach
    seq = [m for i, m in enumerate(modes) if i == 0 or m != modes[i - 1]]
    first = seq.index("pick")
    assert seq[first:first + 3] == ["pick", "to_pick", "pick"]  # at once, not after deciding again
