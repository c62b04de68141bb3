"""``raf sim --paced`` (sim/runner.py): the runner waits for the reply to every frame and applies it in the next
cycle's script call, where a free-running run reads it, so the loop keeps real time's latency in control cycles
without the wall clock (issue 23)."""
import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.sim.runner import RunnerConfig
from robotatfactory.sim.trace import read_trace
from test_sim_control import Controller, start


def drive(seq: int) -> tuple[float, float]:
    """A command that names the frame it answers: V = 1 mm/s per Seq (bounded), W = 0."""
    return (0.001 * (seq % 200), 0.0)


def run_paced(field, robot, path, cycles: int = 60, reply_timing: str = "every_cycle", camera: bool = False,
               hold: int = 1):
    peer = Controller(drive)
    runner, t, box = start(field, robot, peer.sock.getsockname(), mode="paced", trace=str(path),
                           duration=cycles * robot.control_period, lockstep_timeout=5.0, pace_hold=hold,
                           sim={"reply_timing": reply_timing, "camera": camera})
    try:
        t.join(60)
        assert not t.is_alive(), "the paced run did not end"
    finally:
        peer.close()
    return box["result"], read_trace(path)


def test_paced_applies_the_reply_to_frame_k_during_cycle_k_plus_2(field, robot, tmp_path):
    result, trace = run_paced(field, robot, tmp_path / "a.jsonl")
    rec = trace.records
    assert len(rec) == 60 and result.counters["timeouts"] == 0
    # every reply came (the runner waited for each) and each was applied once
    assert result.counters["replies"] == 60 and result.counters["applied"] == 59
    # the record of frame k ran the command applied during (t(k-1), t(k)]: the reply to frame k - 2
    for r in rec[2:]:
        assert r.cmd[0] == pytest.approx(drive(r.seq - 2)[0], abs=1e-9), r.seq
    assert rec[0].cmd[:2] == rec[1].cmd[:2] == (0.0, 0.0)  # nothing answered yet


def test_pace_hold_2_applies_the_reply_to_frame_k_a_cycle_later(field, robot, tmp_path):
    """``pace_hold=2``, for a controller that answers frame k with its decision on frame k (the paced whole
    stack): the reply to frame k acts during (t(k+2), t(k+3)], as the answer to frame k does in real time."""
    result, trace = run_paced(field, robot, tmp_path / "a.jsonl", hold=2)
    rec = trace.records
    assert result.counters["replies"] == 60 and result.counters["applied"] == 58
    for r in rec[3:]:
        assert r.cmd[0] == pytest.approx(drive(r.seq - 3)[0], abs=1e-9), r.seq
    assert all(r.cmd[:2] == (0.0, 0.0) for r in rec[:3])


def test_paced_frames_count_the_camera_frames_and_stamp_them(field, robot):
    """Paced, each SensorFrame says how many camera frames came before it (CamN) and each camera frame
    travels with its simulation time (a two-part ZMQ message)."""
    import zmq

    from robotatfactory.simtwo import SensorFrame
    from robotatfactory.simtwo.camera import parse_camera_header

    import time

    from robotatfactory.proc import free_port
    from test_sim_control import request

    port = free_port()
    peer = Controller(drive)
    sub = zmq.Context.instance().socket(zmq.SUB)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    try:
        runner, t, box = start(field, robot, peer.sock.getsockname(), mode="paced", duration=2.0,
                               lockstep_timeout=5.0, camera_bind=f"tcp://127.0.0.1:{port}",
                               start_paused=True, sim={"camera": True})
        sub.connect(f"tcp://127.0.0.1:{port}")
        time.sleep(0.5)  # the subscription reaches the publisher before the first frame
        assert request(runner.control_address, {"op": "resume"})["ok"]
        t.join(60)
        assert not t.is_alive()
        frames = []
        while sub.poll(200):
            frames.append(sub.recv_multipart())
    finally:
        peer.close()
        sub.close(0)
    heads = [parse_camera_header(f[0]) for f in frames]
    assert frames and all(len(f) == 2 for f in frames) and None not in heads
    cam = robot.camera
    assert all(len(f[1]) == cam.width * cam.height * 4 for f in frames)
    assert [i for _, i in heads] == list(range(len(heads)))
    counts = [SensorFrame.decode(d).camera_frames for d in peer.frames]
    assert counts[-1] == len(frames) and counts == sorted(counts)
    # a frame's stamp is at or before the SensorFrame that first counts it
    for d in peer.frames:
        f = SensorFrame.decode(d)
        assert all(heads[j][0] <= f.time + 1e-9 for j in range(f.camera_frames))


def test_two_paced_runs_are_identical(field, robot, tmp_path):
    """The same seed, paced: the same trace, cycle by cycle (camera on: SimTwo's GUI-turn model decides which
    script calls read replies, from the seed)."""
    _, a = run_paced(field, robot, tmp_path / "a.jsonl", 100, "simtwo", camera=True)
    _, b = run_paced(field, robot, tmp_path / "b.jsonl", 100, "simtwo", camera=True)
    assert len(a.records) == 100
    assert [(r.seq, r.pose, r.cmd) for r in a.records] == [(r.seq, r.pose, r.cmd) for r in b.records]


def test_a_script_call_that_reads_nothing_keeps_the_replies_for_the_next(field, robot, tmp_path, monkeypatch):
    """SimTwo's reply reading (``replies_readable``) still applies paced: a call that cannot read leaves the
    command as it was, and the next call applies the first of the replies held (SimTwo's first-wins)."""
    from robotatfactory.sim import Simulator

    monkeypatch.setattr(Simulator, "replies_readable", lambda self: self.seq % 10 != 5)
    res, tr = run_paced(field, robot, tmp_path / "a.jsonl", 60, "simtwo")
    by_seq = {r.seq: round(r.cmd[0] / 0.001) for r in tr.records}  # the frame each cycle's command answered
    assert res.counters["replies_deferred"] == 6 and res.counters["superseded"] == 6
    for k in range(2, 60):
        # the script call after frame k runs at the simulator's seq k + 1: it reads nothing when (k + 1) % 10 == 5,
        # so cycle k + 1 keeps the reply to k - 2 and the next call applies the reply to k - 1 (the first held;
        # the reply to k is superseded): the records of frames 5, 6, 15, 16, ... one reply late, then in step
        late = k % 10 in (5, 6)
        assert by_seq[k] == k - 2 - late, (k, by_seq[k])


def test_paced_and_lockstep_exclude_each_other():
    with pytest.raises(ConfigError, match="paced"):
        RunnerConfig(mode="paced", lockstep=True)


def _through_lossy_link(field, robot, path, notify: bool, cycles: int = 60, timeout: float = 5.0):
    """A paced run whose frames and replies cross the faults proxy, dropping 20 % of each way (seeded)."""
    from robotatfactory.experiments._faults_net import LOCAL, Proxy

    peer = Controller(drive)
    proxy = Proxy((LOCAL, peer.sock.getsockname()[1]), seed=7, notify_lost=notify)
    proxy.set_faults(0.2)
    runner, t, box = start(field, robot, (LOCAL, proxy.port), mode="paced", trace=str(path),
                           duration=cycles * robot.control_period, lockstep_timeout=timeout, pace_hold=2)
    try:
        t.join(120)
        assert not t.is_alive(), "the paced run did not end"
    finally:
        peer.close()
        proxy.close()
    return box["result"], read_trace(path), proxy


def test_a_lossy_link_tells_a_paced_run_what_it_lost(field, robot, tmp_path):
    """Paced, the runner waits for the reply to every frame; the proxy's notice of a lost frame or reply
    (``LINK_LOST``) ends that wait at once, and the cycle keeps the command it had, as a lost reply does in
    real time. Without the notice every loss costs the whole reply timeout."""
    res, tr, proxy = _through_lossy_link(field, robot, tmp_path / "a.jsonl", notify=True)
    c = res.counters
    lost = proxy.counts["dropped"]
    assert lost >= 5 and proxy.counts["lost_notices"] == lost
    assert c["timeouts"] == 0 and c["link_lost"] == lost
    assert len(tr.records) == 60 and c["replies"] + c["link_lost"] >= 60
    # a cycle whose reply was lost runs the command before it: every command answers an earlier frame
    assert all(r.cmd[0] <= drive(max(r.seq - 3, 0))[0] + 1e-9 for r in tr.records)
    assert sum(r.cmd[0] == drive(r.seq - 3)[0] for r in tr.records[3:]) < 57  # some cycles kept an older one

    res2, _, proxy2 = _through_lossy_link(field, robot, tmp_path / "b.jsonl", notify=False, timeout=0.2)
    assert proxy2.counts["dropped"] >= 5 and res2.counters["timeouts"] >= 5 and res2.counters["link_lost"] == 0


def test_a_paced_run_never_applies_a_reply_older_than_one_applied(field, robot, tmp_path):
    """A controller that answers every frame, then sends the answer to the frame before it again (a duplicate,
    or a reply a lossy link held back): raf sim counts each late one as stale and never applies it, so the run
    is the one the plain controller gives (when a late reply comes depends on the machine's timing)."""
    from robotatfactory.simtwo import Command

    class Repeating(Controller):
        def answer(self, f, addr) -> None:
            super().answer(f, addr)
            if f.seq > 0:  # the previous answer again, with another speed: it must not act
                self.sock.sendto(Command(0.9, 0.0, False, f.seq - 1).encode(), addr)

    _, plain = run_paced(field, robot, tmp_path / "a.jsonl", hold=2)
    peer = Repeating(drive)
    runner, t, box = start(field, robot, peer.sock.getsockname(), mode="paced", trace=str(tmp_path / "b.jsonl"),
                           duration=60 * robot.control_period, lockstep_timeout=5.0, pace_hold=2,
                           sim={"reply_timing": "every_cycle", "camera": False})
    try:
        t.join(60)
        assert not t.is_alive()
    finally:
        peer.close()
    c = box["result"].counters
    assert c["stale"] >= 58 and c["timeouts"] == 0
    late = read_trace(tmp_path / "b.jsonl")
    assert [(r.seq, r.cmd) for r in late.records] == [(r.seq, r.cmd) for r in plain.records]


def test_a_paced_run_answers_after_a_reset(field, robot):
    """sim/reset restarts Seq at 0: the replies to the new frames are new, not older than the last one before
    (the check that drops a late reply starts again), and none waits out the reply timeout."""
    from test_sim_control import request, stop

    peer = Controller(drive)
    runner, t, _ = start(field, robot, peer.sock.getsockname(), mode="paced", start_paused=True,
                         lockstep_timeout=1.0, pace_hold=2, sim={"camera": False})
    addr = runner.control_address
    try:
        assert request(addr, {"op": "step", "cycles": 30})["ok"]
        assert request(addr, {"op": "reset"})["ok"]
        assert request(addr, {"op": "step", "cycles": 20})["ok"]
        c = runner.counters
        assert c.timeouts == 0 and c.replies == 50 and c.stale == 0
    finally:
        stop(runner, t)
        peer.close()
