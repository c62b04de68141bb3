"""competition.live.LiveReferee: a referee fed with reported positions (the real SimTwo's), as the stand-in's."""
import math

import pytest
from robotatfactory.competition import RoundSetup
from robotatfactory.competition.live import LiveReferee
from robotatfactory.errors import ConfigError
from robotatfactory.field import load_field
from robotatfactory.robot import load_robot
from robotatfactory.sim.trace import read_trace

FIELD = load_field("simtwo2022")
ROBOT = load_robot()
START = (0.0, -0.35, math.pi / 2)


def _slot_parts(live):
    return {pid: (*FIELD.slot("incoming", pid).xy, 0.0) for pid in live.ids}


def test_a_blue_part_carried_to_outgoing_scores_once_and_the_trace_reads_back(tmp_path):
    live = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=1.0, trace=tmp_path / "t.jsonl",
                       seed=7)
    parts = _slot_parts(live)
    t = 0.0
    for k in range(50):  # 2 s at rest: the run starts at 1 s
        t = 0.04 * (k + 1)
        live.cycle(t, k, START, parts, magnet=False)
    assert live.factory.started and live.factory.start_time == pytest.approx(1.04)
    assert live.report().points == 0
    out = FIELD.slot("outgoing", 2)
    parts[1] = (*out.xy, 0.0)
    for k in range(50, 60):
        t = 0.04 * (k + 1)
        live.cycle(t, k, START, parts, magnet=False, enc=(k, -k), cmd=(0.1, 0.0, True))
    rep = live.report()
    assert (rep.points, rep.max_points) == (1, 1) and rep.last_score_time == pytest.approx(2.04 - 1.04)
    assert live.max_held_for(0.3) and not live.max_held_for(1.0)
    live.close()
    trace = read_trace(tmp_path / "t.jsonl")
    assert trace.head["round"] == 1 and trace.head["parts"] == {"1": "B"}
    assert len(trace.records) == 60 and trace.records[-1].parts[1][:2] == pytest.approx(out.xy, abs=1e-5)
    assert trace.records[-1].enc == (59, -59) and trace.records[-1].cmd == (0.1, 0.0, True)


def test_held_is_the_part_against_the_magnet_while_it_is_on():
    live = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"))
    x, y, th = 0.2, 0.1, 0.3
    ahead = live.held_x
    part = {1: (x + ahead * math.cos(th), y + ahead * math.sin(th), 0.0)}
    assert live.held((x, y, th), part, magnet=True) == 1
    assert live.held((x, y, th), part, magnet=False) is None
    far = {1: (x + (ahead + 0.05) * math.cos(th), y + (ahead + 0.05) * math.sin(th), 0.0)}
    assert live.held((x, y, th), far, magnet=True) is None


def test_a_held_part_over_a_slot_is_not_delivered_until_let_go():
    live = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=0.0)
    out = FIELD.slot("outgoing", 1)
    # the robot docked at the slot: the part's centre where the magnet holds it
    th = out.facing + math.pi
    rx, ry = out.xy[0] - live.held_x * math.cos(th), out.xy[1] - live.held_x * math.sin(th)
    parts = {1: (*out.xy, 0.0)}
    for k in range(5):
        live.cycle(0.04 * (k + 1), k, (rx, ry, th), parts, magnet=True)
    assert live.report().points == 0
    live.cycle(0.24, 5, (rx, ry, th), parts, magnet=False)
    assert live.report().points == 1


def test_parts_as_a_tuple_are_part_1_to_n_and_unknown_ids_are_ignored():
    live = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=0.0)
    out = FIELD.slot("outgoing", 1)
    live.cycle(0.04, 0, START, ((*out.xy, 0.0), (9.0, 9.0, 0.0)), magnet=False)
    assert live.report().points == 1  # part 2 does not exist in this round: ignored


@pytest.mark.parametrize("kw", [{"start_after": -1.0}, {"start_after": math.nan}, {"held_reach": 0.0},
                                {"ready_timeout": -1.0}])
def test_bad_settings_are_refused(kw):
    with pytest.raises(ConfigError):
        LiveReferee(FIELD, ROBOT, RoundSetup.make(1), **kw)


def test_waiting_for_the_robot_the_run_starts_once_it_is_ready_or_at_the_timeout():
    """SimTwo on a 2-core machine streams its camera seconds after its first frame: a robot without a camera fix
    had no pose for 1.6-10 s of the run (stop 41). With ``wait_ready`` the run starts at the first cycle after
    both ``start_after`` and :meth:`LiveReferee.set_ready`; a robot that never says it is ready gets the run at
    ``ready_timeout``."""
    live = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=1.0, wait_ready=True)
    parts = _slot_parts(live)
    for k in range(100):  # 4 s: past start_after, not ready
        live.cycle(0.04 * (k + 1), k, START, parts, magnet=False)
    assert not live.factory.started
    live.set_ready()
    assert live.ready_at == pytest.approx(4.0)
    live.cycle(4.04, 100, START, parts, magnet=False)
    assert live.factory.started and live.factory.start_time == pytest.approx(4.04) and not live.started_unready
    early = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=1.0, wait_ready=True)
    early.cycle(0.04, 0, START, parts, magnet=False)
    early.set_ready()  # ready before start_after: the start waits for start_after
    for k in range(1, 30):
        early.cycle(0.04 * (k + 1), k, START, parts, magnet=False)
    assert early.factory.start_time == pytest.approx(1.04)
    never = LiveReferee(FIELD, ROBOT, RoundSetup.make(1, parts="BXXX"), start_after=1.0, wait_ready=True,
                        ready_timeout=2.0)
    for k in range(60):
        never.cycle(0.04 * (k + 1), k, START, parts, magnet=False)
    assert never.factory.started and never.factory.start_time == pytest.approx(2.04) and never.started_unready
