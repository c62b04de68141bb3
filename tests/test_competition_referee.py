"""The referee against the rules: blue counts once, green up to twice, red up to three times; only
correct places score; only during the run; a part scores where it rests at the end (knocked out: its point
is lost; put back: it scores again); the time is when the final score was reached and held; ties by parts in
the outgoing warehouse, then time."""
import pytest

from robotatfactory.competition import KinematicWorld, PartType, Referee, RoundSetup, ScoreReport
from robotatfactory.field import load_field

FIELD = load_field()
R, G, B = PartType.RED, PartType.GREEN, PartType.BLUE


def world(parts, round_no=3, delay=1.0, duration=600.0, **kw):
    w = KinematicWorld(FIELD, RoundSetup.make(round_no, parts=parts, processing_delay=delay, duration=duration),
                       **kw)
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
    # picked up in between, the part was out of the warehouse: the final score stands since the last placement
    assert rep.last_score_time == pytest.approx(rep.events[-1].elapsed) and rep.events[-1].points == 1
    assert [e.points for e in rep.events] == [1, -1, 1, -1, 1, -1, 1] and rep.lost == 3


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


# ------------------------------------------------------------------ a part counts where it rests at the end
def test_a_part_knocked_out_after_it_scored_loses_its_point():
    w = world("BBXX", round_no=1)
    fetch(w, 1, "outgoing", 1)
    w.advance(2.0)
    fetch(w, 2, "outgoing", 2)
    t_two = w.t
    assert w.report().points == 2
    w.advance(1.0)
    w.move_part(1, (0.245, -0.45))  # pushed 8.5 cm out of its slot by the robot
    w.step()
    t_out = w.t
    w.advance(1.0)
    rep = w.report()
    assert rep.points == 1 and rep.outgoing == 1 and rep.lost == 1
    assert rep.events[-1].points == -1 and rep.events[-1].part_id == 1 and rep.events[-1].t == pytest.approx(t_out)
    # the final score (1) was first reached at part 1's delivery and never fell below it since
    assert rep.last_score_time == pytest.approx(rep.events[0].elapsed)
    assert "left outgoing warehouse slot 1" in str(rep) and "1 point(s) lost on the way" in str(rep)
    assert Referee(w.factory).report(t_two).points == 2  # as if the run had ended before the knock


def test_scored_knocked_out_and_put_back_scores_again_at_the_later_time():
    w = world("BXXX", round_no=1)
    fetch(w, 1, "outgoing", 2)
    first = w.report().last_score_time
    w.advance(1.0)
    w.move_part(1, (0.395, -0.45))  # knocked out
    w.step()
    w.advance(2.0)
    assert w.report().points == 0 and w.report().last_score_time is None
    fetch(w, 1, "outgoing", 2)  # put back
    rep = w.report()
    assert rep.points == 1 and rep.outgoing == 1
    assert [e.points for e in rep.events] == [1, -1, 1]
    assert rep.last_score_time == pytest.approx(rep.events[-1].elapsed) and rep.last_score_time > first + 2.5


def test_final_score_reached_lost_reached_again_the_time_is_the_last_reaching():
    w = world("BBBX", round_no=1)
    fetch(w, 1, "outgoing", 1)
    fetch(w, 2, "outgoing", 2)
    w.advance(1.0)
    fetch(w, 3, "outgoing", 3)  # 3: the final score, first reached
    first = w.report().last_score_time
    w.advance(1.0)
    w.move_part(2, (0.395, -0.40))  # 2: knocked out
    w.step()
    w.advance(3.0)
    assert w.report().points == 2
    fetch(w, 2, "outgoing", 2)  # 3 again
    rep = w.report()
    assert rep.points == 3 and rep.last_score_time > first + 3.5
    assert rep.last_score_time == pytest.approx(rep.events[-1].elapsed)


def test_a_higher_score_lost_leaves_the_time_the_final_score_was_first_held():
    w = world("BBXX", round_no=1)
    fetch(w, 1, "outgoing", 1)
    held_from = w.report().last_score_time
    w.advance(2.0)
    fetch(w, 2, "outgoing", 2)  # 2 points for a while
    w.advance(1.0)
    w.move_part(2, (0.395, -0.40))  # knocked out again: the final score is 1, held since part 1's delivery
    w.step()
    rep = w.report()
    assert rep.points == 1 and rep.last_score_time == pytest.approx(held_from)


def test_a_part_in_a_machine_picked_up_again_loses_the_point_but_a_processed_part_keeps_it():
    w = world("RXXX", delay=2.0)
    fetch(w, 1, "machine_A", 1)
    assert w.report().points == 1
    w.pick(1)  # taken away before the machine finished: no longer delivered
    assert w.report().points == 0
    w.place(1, "machine_A", 1)
    w.advance(2.5)  # processed: green at the output, machine A's point banked
    assert w.factory.part_type(1) is G and w.report().points == 1
    w.pick(1)
    w.move_part(1, (0.0, -0.3))
    w.held.clear()  # dropped on the floor on the way to machine B: the banked point stays
    w.step()
    rep = w.report()
    assert rep.points == 1 and [e.points for e in rep.events] == [1, -1, 1]


def test_the_state_at_the_end_of_the_round_is_final():
    w = world("BXXX", round_no=1, duration=5.0)
    fetch(w, 1, "outgoing", 1)
    w.advance(6.0)  # the round is over
    w.move_part(1, (0.245, -0.40))  # knocked out after the end: does not count
    w.step()
    rep = w.report()
    assert rep.points == 1 and rep.outgoing == 1 and rep.lost == 0


def test_live_referee_and_the_runner_take_a_lost_maximum_back():
    from robotatfactory.competition.live import LiveReferee
    from robotatfactory.robot import load_robot

    live = LiveReferee(FIELD, load_robot(), RoundSetup.make(1, parts="BXXX"), start_after=0.0)
    slot = FIELD.slot("outgoing", 1)
    part = (-0.695, 0.535, 0.0)
    t = 0.0
    for k in range(5):
        t += 0.04
        live.cycle(t, k, (-0.725, -0.4, 1.57), {1: part}, False)
    for k in range(30):  # delivered and left there 1.2 s
        t += 0.04
        live.cycle(t, k, (-0.725, -0.4, 1.57), {1: (*slot.xy, 0.0)}, False)
    assert live.max_held_for(1.0)
    t += 0.04
    live.cycle(t, 99, (-0.725, -0.4, 1.57), {1: (slot.xy[0], slot.xy[1] + 0.1, 0.0)}, False)
    assert not live.max_held_for(0.0) and live.max_at is None and live.report().points == 0


def test_the_experiments_read_the_same_score_from_the_report_text():
    """raf sim and raf referee print str(report); the competition experiment reads it back (_competition_log)."""
    from robotatfactory.experiments._competition_log import parse_sim_report, points_lost

    w = world("BBXX", round_no=1)
    fetch(w, 1, "outgoing", 1)
    w.advance(1.0)
    fetch(w, 2, "outgoing", 2)
    w.move_part(2, (0.395, -0.40))
    w.step()
    rep = w.report()
    points, max_points, last, found = parse_sim_report(str(rep))
    assert found and (points, max_points) == (rep.points, rep.max_points) == (1, 2)
    assert last == pytest.approx(rep.last_score_time, abs=0.01) and points_lost(str(rep)) == rep.lost == 1
    fetch(w, 2, "outgoing", 2)
    assert points_lost(str(w.report())) == 1 and parse_sim_report(str(w.report()))[0] == 2


def test_the_report_has_the_factorys_counters():
    """The final report (raf sim, raf referee) says what the machines did and whether a teleport never showed in
    the positions (on SimTwo: the bridge lost it), which the score alone does not."""
    from robotatfactory.competition.factory import TELEPORT_GRACE
    from robotatfactory.experiments._competition_log import notes_of, parse_sim_report, points_lost

    w = world("GRXX", delay=1.0, teleport_delay=None)  # the simulator never applies a teleport
    fetch(w, 2, "machine_A", 1)
    w.advance(0.2)  # the machine took it
    w.pick(2)  # and it is taken back before the machine finished: cancelled
    w.place(2, "incoming", 2)
    fetch(w, 1, "machine_B", 1)
    w.advance(1.0 + TELEPORT_GRACE + 0.5)  # processed, then late: the positions count again
    rep = w.report()
    assert (rep.processed, rep.cancelled, rep.teleports_late) == (1, 1, 1)
    text = str(rep)
    assert "  factory counters: processed 1, cancelled 1, teleports_late 1" in text.splitlines()
    assert parse_sim_report(text)[:2] == (rep.points, rep.max_points) and points_lost(text) == rep.lost
    assert notes_of(text) == []
