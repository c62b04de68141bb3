"""The referee against the rules: blue counts once, green up to twice, red up to three times; only
correct places score; only during the run; ties by parts in the outgoing warehouse, then time."""
import pytest

from robotatfactory.competition import KinematicWorld, PartType, Referee, RoundSetup, ScoreReport
from robotatfactory.field import load_field

FIELD = load_field()
R, G, B = PartType.RED, PartType.GREEN, PartType.BLUE


def world(parts, round_no=3, delay=1.0, duration=600.0):
    w = KinematicWorld(FIELD, RoundSetup.make(round_no, parts=parts, processing_delay=delay, duration=duration))
    w.start()
    return w


def fetch(w, pid, zone, number):
    """Pick part pid wherever it is and place it in (zone, number); the robot then leaves."""
    w.pick(pid)
    w.place(pid, zone, number)


def test_round_1_four_blue_parts_to_outgoing():
    w = world("BBBB", round_no=1)
    for pid in (1, 2, 3, 4):
        w.advance(5.0)
        fetch(w, pid, "outgoing", 5 - pid)
    rep = w.report()
    assert rep.points == 4 and rep.outgoing == 4
    assert rep.last_score_time == pytest.approx(w.t)  # the last placement was the last cycle
    assert [e.part_id for e in rep.events] == [1, 2, 3, 4]


def test_red_part_through_both_machines_scores_three():
    w = world("RXXX", delay=2.0)
    fetch(w, 1, "machine_A", 1)
    assert w.report().points == 1  # delivered to machine A
    w.advance(2.5)
    assert w.factory.part_type(1) is G and w.factory.slot_of(1) == w.slot("machine_A", 2)
    assert w.report().points == 1  # the machine giving it back is not a delivery
    fetch(w, 1, "machine_B", 3)
    assert w.report().points == 2
    w.advance(2.5)
    assert w.factory.part_type(1) is B
    fetch(w, 1, "outgoing", 2)
    rep = w.report()
    assert rep.points == 3 and rep.outgoing == 1
    assert [(e.part_type, e.stage) for e in rep.events] == [(R, "machine_A"), (G, "machine_B"), (B, "outgoing")]


def test_green_part_scores_twice_blue_once():
    w = world("XGBX", delay=0.5)
    fetch(w, 2, "machine_B", 1)
    w.advance(1.0)
    fetch(w, 2, "outgoing", 1)
    fetch(w, 3, "outgoing", 2)
    rep = w.report()
    assert rep.points == 3 and rep.outgoing == 2 and rep.max_points == 3


@pytest.mark.parametrize("parts, pid, zone, number", [
    ("RXXX", 1, "outgoing", 1),      # red straight to the outgoing warehouse
    ("BXXX", 1, "machine_A", 1),     # blue into a machine
    ("XGXX", 2, "machine_A", 3),     # green into the wrong machine
    ("RXXX", 1, "machine_B", 1),     # red into machine B
    ("RXXX", 1, "machine_A", 2),     # the output side of the right machine
    ("BXXX", 1, "incoming", 2),      # back into the incoming warehouse
])
def test_wrong_places_do_not_score(parts, pid, zone, number):
    w = world(parts, delay=0.5)
    fetch(w, pid, zone, number)
    w.advance(2.0)
    rep = w.report()
    assert rep.points == 0 and rep.outgoing == 0 and rep.events == () and rep.last_score_time is None


def test_each_delivery_counts_once_per_part():
    w = world("BXXX")
    for n in (1, 2, 1, 3):  # moved around inside the outgoing warehouse
        fetch(w, 1, "outgoing", n)
    rep = w.report()
    assert rep.points == 1 and rep.outgoing == 1
    assert rep.last_score_time == pytest.approx(rep.events[0].elapsed)  # the first delivery counts


def test_red_dropped_twice_at_machine_a_before_processing_counts_once():
    w = world("RXXX", delay=5.0)
    fetch(w, 1, "machine_A", 1)
    fetch(w, 1, "machine_A", 3)
    assert w.report().points == 1


def test_placements_before_the_start_or_after_the_end_do_not_count():
    w = KinematicWorld(FIELD, RoundSetup.make(1, parts="BBXX", duration=10.0))
    fetch(w, 1, "outgoing", 1)  # before the start (a robot must not move then)
    assert not w.report().started and w.report().points == 0
    w.start()
    t0 = w.t
    rep = w.report()
    assert rep.points == 0  # already lying there when the run started: not a placement during the run
    w.advance(10.5)
    fetch(w, 2, "outgoing", 2)
    rep = w.report()
    assert rep.points == 0 and rep.time_left == 0.0
    assert w.factory.start_time == t0


def test_report_at_an_earlier_time_ignores_later_deliveries():
    w = world("BBXX")
    fetch(w, 1, "outgoing", 1)
    t_mid = w.t
    w.advance(3.0)
    fetch(w, 2, "outgoing", 2)
    ref = Referee(w.factory)
    assert ref.report(t_mid).points == 1 and ref.report(w.t).points == 2


def test_ranking_by_points_then_outgoing_then_time():
    def rep(points, outgoing, last):
        return ScoreReport(points, outgoing, last, (), t=100.0, start_time=0.0, time_left=500.0, round_no=3,
                           layout="RGBB", max_points=7)

    runs = [rep(4, 1, 50.0), rep(5, 0, 300.0), rep(4, 2, 200.0), rep(4, 2, 150.0), rep(0, 0, None)]
    best_first = sorted(runs, key=ScoreReport.rank_key)
    assert [(r.points, r.outgoing, r.last_score_time) for r in best_first] == [
        (5, 0, 300.0), (4, 2, 150.0), (4, 2, 200.0), (4, 1, 50.0), (0, 0, None)]
    assert rep(4, 2, 150.0).beats(rep(4, 2, 200.0)) and not rep(4, 1, 10.0).beats(rep(4, 2, 500.0))


def test_report_text_is_a_readable_table():
    w = world("RXBX", delay=0.5)
    fetch(w, 1, "machine_A", 1)
    fetch(w, 3, "outgoing", 4)
    text = str(w.report())
    assert "Round 3" in text and "RXBX" in text
    assert "machine A slot 1 (input)" in text and "outgoing warehouse slot 4" in text
    assert "total: 2 of 4 points; 1 part(s) in the outgoing warehouse" in text
    assert w.report().short().startswith("score 2/4 (outgoing 1, last at")
    idle = KinematicWorld(FIELD, RoundSetup.make(1))
    assert "not started" in str(idle.report()) and "not started" in idle.report().short()


def test_rule_notes_false_start_and_start_area():
    w = world("BXXX")  # the robot stood still at the start pose (inside the start area): nothing to note
    fetch(w, 1, "outgoing", 1)
    assert w.report().notes == () and "note:" not in str(w.report())

    early = KinematicWorld(FIELD, RoundSetup.make(1, parts="BXXX"))
    early.step()
    early.robot_xy = (-0.725, -0.37)  # 3 cm before the start
    early.step()
    early.start()
    early.step()
    (note,) = early.report().notes
    assert "moved 0.030 m before the run started" in note
    assert "note: the robot moved" in str(early.report())
    assert early.report().points == 0  # a note, not a penalty

    away = KinematicWorld(FIELD, RoundSetup.make(1, parts="BXXX"), robot_xy=(0.0, 0.0))
    away.start()
    away.step()
    (note,) = away.report().notes
    assert "outside the start area" in note


def test_small_jitter_before_the_start_is_not_a_false_start():
    w = KinematicWorld(FIELD, RoundSetup.make(1, parts="BXXX"))
    for dx in (0.0, 0.005, -0.01, 0.015):
        w.robot_xy = (-0.725 + dx, -0.4)
        w.step()
    w.start()
    w.step()
    assert w.report().notes == ()
