"""SensorFrame sequence bookkeeping (robotatfactory.simtwo.stream): pure."""
from __future__ import annotations

import pytest
from hypothesis import given, settings, strategies as st

from robotatfactory.ratelog import LogLimiter
from robotatfactory.simtwo.stream import RateMeter, StreamTracker, Verdict


def feed(tr, seqs, period=40):
    return [tr.offer(s, (s + 1) * period, arrival=float(i)) for i, s in enumerate(seqs)]


def test_in_order_stream():
    tr = StreamTracker()
    ev = feed(tr, range(5))
    assert [e.verdict for e in ev] == [Verdict.FIRST] + [Verdict.NEXT] * 4
    assert ev[0].from_zero
    assert tr.counters.accepted == 5 and tr.counters.lost == 0


def test_joining_a_running_stream_does_not_count_from_zero():
    tr = StreamTracker()
    e = tr.offer(1000, 40040, 0.0)
    assert e.verdict is Verdict.FIRST and not e.from_zero


def test_gap_duplicate_and_reordering():
    tr = StreamTracker()
    ev = feed(tr, [0, 1, 4, 4, 3, 5, 2, 6])
    assert [e.verdict for e in ev] == [Verdict.FIRST, Verdict.NEXT, Verdict.GAP, Verdict.DUPLICATE, Verdict.STALE,
                                       Verdict.NEXT, Verdict.STALE, Verdict.NEXT]
    assert ev[2].lost == 2
    c = tr.counters
    assert (c.received, c.accepted, c.lost, c.gaps, c.duplicates, c.stale, c.restarts) == (8, 5, 2, 1, 1, 2, 0)


def test_restart_after_a_long_run_needs_a_chain_of_frames():
    """One datagram never restarts the stream: a frame like a restart's is held until two more follow it."""
    tr = StreamTracker(reorder_window=25, restart_confirm=3)
    feed(tr, range(100))
    assert tr.offer(0, 40, 200.0).verdict is Verdict.HELD
    assert tr.offer(1, 80, 201.0).verdict is Verdict.HELD
    e = tr.offer(2, 120, 202.0)
    assert e.verdict is Verdict.RESTART and e.from_zero and e.run_length == 3
    assert tr.offer(3, 160, 203.0).verdict is Verdict.NEXT
    assert tr.counters.restarts == 1 and tr.counters.held == 0


def test_restart_soon_after_start_is_confirmed_by_a_run_of_frames():
    tr = StreamTracker(reorder_window=25, restart_confirm=3)
    feed(tr, range(10))
    assert tr.offer(0, 40, 20.0).verdict is Verdict.STALE
    assert tr.offer(1, 80, 21.0).verdict is Verdict.STALE
    e = tr.offer(2, 120, 22.0)
    assert e.verdict is Verdict.RESTART and e.from_zero and e.run_length == 3
    assert tr.counters.stale == 0  # the run's frames were the new stream, not stale ones
    assert tr.offer(3, 160, 23.0).verdict is Verdict.NEXT


def test_scattered_old_frames_do_not_make_a_restart():
    tr = StreamTracker(restart_confirm=3)
    feed(tr, range(20))
    assert [tr.offer(s, (s + 1) * 40).verdict for s in (15, 17, 16, 18)] == [Verdict.STALE] * 4
    assert tr.counters.restarts == 0


def test_clock_going_backwards_with_seq_ahead_is_a_restart_once_confirmed():
    tr = StreamTracker()
    feed(tr, range(10))
    e = tr.offer(50, 2040, 30.0)  # seq and time ahead: a gap
    assert e.verdict is Verdict.GAP
    assert tr.offer(60, 100, 31.0).verdict is Verdict.HELD  # restarted while we were not receiving?
    assert tr.offer(61, 140, 32.0).verdict is Verdict.HELD
    e = tr.offer(62, 180, 33.0)
    assert e.verdict is Verdict.RESTART and not e.from_zero


def test_far_behind_restart_from_nonzero_seq_does_not_count_from_zero():
    tr = StreamTracker(reorder_window=25)
    feed(tr, range(200))
    assert [tr.offer(s, (s + 1) * 40, 300.0 + s).verdict for s in (77, 78)] == [Verdict.HELD] * 2
    e = tr.offer(79, 3200, 400.0)
    assert e.verdict is Verdict.RESTART and not e.from_zero


def test_rejects_are_counted_by_kind():
    tr = StreamTracker()
    tr.reject("malformed")
    tr.reject("malformed")
    tr.reject("foreign_source")
    assert tr.counters.rejected["malformed"] == 2 and tr.counters.rejected_total == 3
    assert tr.counters.as_dict()["rejected_foreign_source"] == 1
    with pytest.raises(ValueError):
        tr.reject("nonsense")


def test_staleness_and_reset():
    tr = StreamTracker()
    assert tr.staleness(5.0) is None
    tr.offer(0, 40, 10.0)
    assert tr.staleness(12.5) == pytest.approx(2.5)
    tr.reset()
    assert tr.offer(9, 400, 13.0).verdict is Verdict.FIRST


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 60), min_size=1, max_size=80))
def test_accepted_frames_are_strictly_increasing_without_restarts(seqs):
    """Whatever arrives (duplicates, reordering, gaps, no restart: Tms follows Seq), accepted Seq only grow,
    and lost + accepted covers exactly the span of accepted sequence numbers."""
    tr = StreamTracker(reorder_window=1000, restart_confirm=10 ** 6)
    acc = [e.seq for e in (tr.offer(s, (s + 1) * 40) for s in seqs) if e.accepted]
    assert acc == sorted(set(acc))
    assert tr.counters.accepted + tr.counters.lost == acc[-1] - acc[0] + 1
    c = tr.counters
    assert c.received == c.accepted + c.duplicates + c.stale + c.held


def test_rate_meter():
    m = RateMeter(window=2.0)
    assert m.rate(0.0) == 0.0 and m.age(0.0) is None
    for i in range(101):
        m.tick(10.0 + i * 0.02)  # 50 Hz for 2 s
    assert m.rate(12.0) == pytest.approx(50, rel=0.03)
    assert m.age(13.0) == pytest.approx(1.0)
    assert m.rate(20.0) == 0.0  # nothing in the window any more


def test_log_limiter():
    lim = LogLimiter(period=5.0)
    assert lim("bad", 0.0) == ""
    assert lim("bad", 1.0) is None
    assert lim("bad", 2.0) is None
    assert lim("other", 2.0) == ""
    msg = lim("bad", 6.0)
    assert msg is not None and "2 more" in msg
