"""A whole round on the bare stand-in simulator: the agent's behaviour fed only the pose, the contact
switch and the factory-state server's answers (the real FactoryServer on loopback, through the agent's
client). The simulator's ground-truth pose stands in for the EKF only here."""
import pytest

from robotatfactory.agent.behaviour import RoundAgent
from robotatfactory.agent.settings import Tasks
from robotatfactory.experiments.competition import play_round


@pytest.mark.parametrize("round_no,seed", [(1, 0), (3, 0)])
def test_a_round_scores_the_maximum(round_no, seed):
    # the competition experiment's own run, on the rules' field, with the simulator's default magnet (SimTwo's
    # force: the part can slide on the magnet's face and be lost; docs/simulator.md, "The electromagnet")
    r = play_round(round_no, seed)
    print(f"\nround {round_no} seed {seed}: {r['points']}/{r['max_points']} points, last score at "
          f"{r['last_score_s']:.1f} s; delay estimate {r['delay_estimate_s']}")
    assert r["agent_done"]
    assert r["points"] == r["max_points"] and not r["notes"]
    assert r["moved_before_start_cycles"] == 0  # nothing before the part list
    assert r["collision_checks_hit"] == 0  # the outline never met a wall or rib
    assert r["pick_failures"] == r["place_failures"] == 0
    assert r["parts_pushed"] == 0  # nothing knocked out of a slot, no part lost on the floor and pushed
    if round_no == 3:  # the machines' 10 s learned from the server: measured from the magnet's release, it
        # also holds the robot backing out past 0.17 m (about 1 s) and the 0.5 s poll period; never below
        assert 10.0 <= r["delay_estimate_s"] <= 10.0 + 1.5 + Tasks.state_period + 0.2


def test_a_blocked_robot_times_out_gives_up_and_never_loops_forever(field, robot):
    """The pose never changes (the robot is stuck): every leg times out, the part is left alone after
    three failures, and the agent ends instead of retrying forever."""
    from robotatfactory.agent.state import FactoryState

    agent = RoundAgent(field, robot)
    sp = field.start_pose
    pose = (sp.x, sp.y, sp.theta)
    t = 0.0
    while t < 600.0 and agent.mode != "done":
        if agent.wants_state:
            agent.on_state(FactoryState.from_letters("XBXX"), t)
        c = agent.step(t, pose, False)
        assert not c.magnet
        t += robot.control_period
    assert agent.mode == "done", agent.events[-3:]
    assert agent.counters.timeouts == agent.settings.tasks.give_up_after == 3
    assert sum("timeout" in text for _, text in agent.events) == 3
    assert t < 300.0  # three budgets of one leg each, not the round's 600 s
