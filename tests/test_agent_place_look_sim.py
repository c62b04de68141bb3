"""The look at markers before a place on the bare stand-in (dynamics, SimTwo's force magnet): a pose unsure on the
last stretch of a leg to a place stops the robot with its part (``recovery.place_uncertainty_limit``); when the
estimate is sure again the robot goes on and the place succeeds. The kinematic test of the stop itself is in
tests/test_agent_recovery.py; here the robot brakes as the stand-in's robot does, on the carry limits, and stands
where the braking left it."""
import math

import pytest

from robotatfactory.bench.looks import UnsureUntilLooked, after_look
from robotatfactory.experiments.competition import play_round


@pytest.mark.parametrize("round_no,seed", [(1, 0), (2, 1), (3, 2)])
def test_after_a_look_before_a_place_the_place_succeeds(round_no, seed):
    """A 15 mm std on the first leg to a place (the real SimTwo's one unsure place began at 18.6 mm): the robot
    stops on the last 15 cm to look, stands 1 s, goes on along its path and the place goes in at the first try;
    the round ends at the maximum."""
    r = play_round(round_no, seed, record_path=True, uncertainty=UnsureUntilLooked(0.015, 1.0))
    ev = [text for _, text, *_ in r["events"]]
    assert sum(e.startswith("pose unsure before the place") for e in ev) == 1, ev
    a = after_look(r["events"])
    assert a["looked"] and a["first_try"], ev
    assert 1.0 < a["place_s"] < 6.0, a  # the look (1 s), the rest of the leg, the place
    assert r["place_failures"] == 0 and r["points"] == r["max_points"], ev


def test_a_look_whose_std_never_falls_goes_on_after_the_look_patience():
    """The look with a part on (the robot does not turn, so its view does not change) ends once the std has not
    fallen for ``recovery.look_patience`` (3 s), not after ``recovery.relocalize_timeout`` (12 s): here the std
    stays 15 mm however long the robot looks. On it goes along its path, the place goes in at the first try."""
    r = play_round(1, 0, record_path=True, uncertainty=UnsureUntilLooked(0.015, 100.0))
    ev = [(t, text) for t, text, *_ in r["events"]]
    t0 = next(t for t, text in ev if text.startswith("pose unsure before the place"))
    t1, why = next((t, text) for t, text in ev if t > t0 and text.endswith(": going on"))
    assert why.startswith("the pose's std stopped falling with the part on (15 mm"), why
    assert 3.0 <= t1 - t0 <= 3.5, (t0, t1)
    a = after_look(r["events"])
    assert a["first_try"] and a["place_s"] < 8.0, a
    assert r["place_failures"] == 0 and r["points"] == r["max_points"], ev


def test_the_leg_planned_again_after_the_look_began_the_place_off_the_line():
    """Why the robot goes on along its path (``recovery.go_on_after_look``): planned again from where the braking
    left it, a few cm before the leg's end and still on its last curve, the leg turned the robot on the spot and
    the place began 15 deg off the slot's normal; the place gate backed out (round 1 seed 0)."""
    r = play_round(1, 0, record_path=True, agent={"recovery": {"go_on_after_look": False}},
                   uncertainty=UnsureUntilLooked(0.015, 1.0))
    a = after_look(r["events"])
    assert a["looked"] and not a["first_try"], r["events"]
    assert any(text.startswith("place at outgoing 1 failed: off_line") for _, text, *_ in r["events"])


def test_after_look_reads_the_events():
    ev = [(1.0, "picked the blue part from incoming 1"), (5.0, "pose unsure before the place (15 mm): stopping to "
          "look at markers"), (6.0, "pose certain again after 1.0 s"), (7.0, "place at outgoing 1 failed: off_line"),
          (12.5, "placed the blue part in outgoing 2")]
    assert after_look(ev) == {"looked": True, "first_try": False, "place_s": 7.5}
    assert after_look(ev[:3] + ev[4:])["first_try"] is True
    nothing = after_look(ev[:1])
    assert nothing["looked"] is False and math.isnan(nothing["place_s"])
