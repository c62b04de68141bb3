"""``raf sim --trace`` (sim/trace.py): the ground truth written cycle by cycle and read back, and
``--end-after-max``: the run ends once the round's maximum score has stood for that long."""
import json
import math

import pytest

from robotatfactory.sim.trace import Trace, TraceRecord, read_trace
from test_sim_control import Controller, request, start


def test_trace_follows_the_run_and_the_run_ends_after_the_maximum(field, robot, tmp_path):
    path = tmp_path / "trace.jsonl"
    peer = Controller(lambda seq: (0.1, 0.5))
    runner, t, box = start(field, robot, peer.sock.getsockname(), start_paused=True, trace=str(path), lockstep=True,
                           end_after_max=0.4, sim={"round_no": 1, "parts": "BXXX", "start_after": 0.0})
    try:
        addr = runner.control_address
        assert request(addr, {"op": "step", "cycles": 5})["ok"]
        (pid,) = runner.sim.parts.ids  # BXXX: one part
        assert request(addr, {"op": "place_part", "part": pid, "slot": "outgoing_1"})["ok"]
        assert request(addr, {"op": "resume"})["ok"]
        t.join(30)
        assert not t.is_alive(), "the run did not end after its maximum score"
    finally:
        peer.close()
    result = box["result"]
    assert result.reason == "maximum score"
    assert result.report.points == result.report.max_points == 1
    trace = read_trace(path)
    assert trace.head["round"] == 1 and trace.head["parts"] == {str(pid): "B"}
    rec = trace.records
    assert len(rec) == result.counters["cycles"]
    dts = {round(b.t - a.t, 4) for a, b in zip(rec, rec[1:])}
    assert dts == {0.04}
    # the robot was driven (0.1 m/s, 0.5 rad/s): the trace shows it moving and turning
    assert math.dist(rec[0].pose[:2], rec[-1].pose[:2]) > 0.02
    assert rec[-1].cmd[:2] == (0.1, 0.5)
    # the part stands where it was placed: within a few mm of outgoing slot 1's centre, not held
    slot = field.slot("outgoing", 1)
    assert math.dist(rec[-1].parts[pid][:2], slot.xy) < 0.005 and rec[-1].held is None
    # it ended 0.4 s after the maximum (checked once per simulated second), not at once and not much later
    scored_at = result.report.events[-1].t
    assert 0.4 - 1e-6 <= rec[-1].t - scored_at <= 1.5
    # interpolation between two cycles, and None outside the trace
    a, b = rec[10], rec[11]
    mid = trace.pose_at((a.t + b.t) / 2)
    assert mid[0] == pytest.approx((a.pose[0] + b.pose[0]) / 2)
    assert trace.pose_at(rec[-1].t + 1.0) is None and trace.pose_at(rec[10].t) == rec[10].pose
    # a stamp a rounding error past the last cycle (the trace keeps 4 decimals) or before the first: their poses
    assert trace.pose_at(rec[-1].t + 5e-10) == rec[-1].pose and trace.pose_at(rec[0].t - 5e-10) == rec[0].pose


def test_a_trace_cut_short_keeps_its_records_and_bad_lines_are_named(tmp_path):
    head = json.dumps({"trace": 1, "control_period": 0.04, "parts": {"1": "B"}, "round": 1, "seed": 0})
    line = json.dumps({"t": 0.04, "seq": 0, "pose": [0, 0, 0], "held": None, "cmd": [0, 0, False],
                       "contact": False, "enc": [0, 0], "parts": [[1, 0.1, 0.2, 0.0]]})
    p = tmp_path / "t.jsonl"
    p.write_text(head + "\n" + line + "\n" + line[:30])  # the writer killed mid-line
    tr = read_trace(p)
    assert isinstance(tr, Trace) and len(tr.records) == 1 and isinstance(tr.records[0], TraceRecord)
    assert tr.records[0].parts == {1: (0.1, 0.2, 0.0)}
    p.write_text(head + "\n" + line[:30] + "\n" + line + "\n")
    with pytest.raises(ValueError, match=":2: not JSON"):
        read_trace(p)
    p.write_text(json.dumps({"hello": 1}) + "\n")
    with pytest.raises(ValueError, match="not a raf sim trace"):
        read_trace(p)


def test_bad_end_after_max_is_a_clear_error():
    from robotatfactory.errors import ConfigError
    from robotatfactory.sim.runner import RunnerConfig

    with pytest.raises(ConfigError, match="--end-after-max"):
        RunnerConfig(end_after_max=-1.0)
