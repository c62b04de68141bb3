"""agent/predict.py: the pose carried through the commands in flight (raf agent steers the pose at the moment
its command will act: the whole stack's loop is two control cycles)."""
import pytest

from robotatfactory.agent.predict import InFlight, extrapolate


def test_the_commands_in_flight_carry_the_pose_forward():
    f = InFlight(0.08, 0.04)
    assert f.ahead((0.0, 0.0, 0.0), 0.0) == (0.0, 0.0, 0.0)  # nothing sent yet
    f.sent(0.0, 0.1, 0.0)
    # one command known, two cycles in flight: it stands in for the missing one
    assert f.ahead((0.0, 0.0, 0.0), 0.04)[0] == pytest.approx(0.008)
    f.sent(0.04, 0.2, 0.0)
    assert f.ahead((0.0, 0.0, 0.0), 0.08)[0] == pytest.approx(0.1 * 0.04 + 0.2 * 0.04)
    f.sent(0.08, 0.3, 0.0)  # the first has run by now: the last two are in flight
    assert f.ahead((0.0, 0.0, 0.0), 0.12)[0] == pytest.approx(0.2 * 0.04 + 0.3 * 0.04)


def test_a_turn_in_flight_is_exact_on_the_arc_and_zero_latency_is_now():
    f = InFlight(0.08, 0.04)
    for k in range(3):
        f.sent(0.04 * k, 0.2, 2.0)
    x, y, th = f.ahead((1.0, 2.0, 0.5), 0.12)
    assert (x, y, th) == pytest.approx(extrapolate((1.0, 2.0, 0.5), 0.2, 2.0, 0.08))
    assert th == pytest.approx(0.5 + 0.16)
    g = InFlight(0.0, 0.04)
    g.sent(0.0, 1.0, 1.0)
    assert g.ahead((1.0, 2.0, 0.5), 0.04) == (1.0, 2.0, 0.5)
    with pytest.raises(ValueError):
        InFlight(-0.1, 0.04)
