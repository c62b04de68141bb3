"""The one rate-limited logger (robotatfactory/ratelog.py) the simulator, the competition server and the
nodes share (LogLimiter's own cases: test_bridge_stream.py)."""
import logging

from robotatfactory.ratelog import RateLimitedLog


def test_the_first_of_a_kind_is_logged_then_one_per_period_with_the_count_held_back(caplog):
    now = [0.0]
    log = RateLimitedLog(logging.getLogger("raf.test.ratelog"), period=5.0, clock=lambda: now[0])
    with caplog.at_level(logging.WARNING, logger="raf.test.ratelog"):
        assert log.warn("bad", "bad value %r from %s", 7, "a")
        now[0] = 1.0
        assert not log.warn("bad", "bad value %r from %s", 8, "b")
        assert not log.warn("bad", "bad value %r from %s", 9, "c")
        assert log.warn("other", "another kind")  # keys are apart
        now[0] = 5.5
        assert log.warn("bad", "bad value %r from %s", 10, "d")
    assert [r.getMessage() for r in caplog.records] == [
        "bad value 7 from a", "another kind", "bad value 10 from d (2 more like this in the last 6 s)"]
