"""Issue 10, stream integrity: one sender per stream, forged and far-future frames held, restarts only from the
bound source with a chain of frames, takeover after silence, impossible encoder counts rejected, loopback
defaults, one controller for ``raf sim``'s command port. The bridge's datagram path runs here without a ROS
master (publishing is recorded, replies go to a fake socket)."""
from __future__ import annotations

import socket
import threading
from pathlib import Path

import pytest

from robotatfactory.simtwo import Command, SensorFrame
from robotatfactory.simtwo.stream import (ERROR, OK, WARN, SourceGate, StreamTracker, Verdict, chain_consistent,
                                          stream_health)

SIM = ("127.0.0.1", 9808)
OTHER = ("127.0.0.1", 40001)


def frame(seq, tms=None, totals=None, x=0.0):
    tms = (seq + 1) * 40 if tms is None else tms
    totals = (seq * 3, seq * 3) if totals is None else totals
    return SensorFrame(seq=seq, time_ms=tms, enc_delta=(3, 3), enc_total=totals, x=x, y=0.0, theta=0.0,
                       contact=False, magnet=False)


# ---- the pure parts ------------------------------------------------------------------------------------------

def test_chain_consistency():
    assert chain_consistent((5, 240), (6, 280), 40, 25)
    assert chain_consistent((5, 240), (9, 400), 40, 25)  # 3 lost in between, time moved as much
    assert not chain_consistent((5, 240), (6, 2000), 40, 25)  # time does not follow Seq
    assert not chain_consistent((5, 240), (5, 240), 40, 25)
    assert not chain_consistent((5, 240), (100, 3840), 40, 25)  # further than the window


def test_a_forged_far_future_frame_is_held_and_changes_nothing():
    tr = StreamTracker(max_jump=250)
    for s in range(20):
        tr.offer(s, (s + 1) * 40, float(s))
    for seq, tms in ((10 ** 9, 840), (21, 10 ** 9), (2 ** 31 - 1, 2 ** 31 - 1), (-5, 10 ** 6)):
        e = tr.offer(seq, tms, 30.0)
        assert e.verdict is Verdict.HELD and not e.accepted
        assert (tr.last_seq, tr.last_time_ms) == (19, 800)
    assert tr.offer(20, 840, 31.0).verdict is Verdict.NEXT
    assert tr.counters.held == 4 and tr.counters.restarts == 0


def test_a_jump_ahead_confirmed_by_a_chain_is_a_gap():
    """A long outage (more than max_jump cycles) is accepted once three frames in a row confirm it."""
    tr = StreamTracker(max_jump=250, restart_confirm=3)
    for s in range(10):
        tr.offer(s, (s + 1) * 40, float(s))
    assert [tr.offer(s, (s + 1) * 40, 20.0).verdict for s in (500, 501)] == [Verdict.HELD] * 2
    e = tr.offer(502, 503 * 40, 21.0)
    assert e.verdict is Verdict.GAP and e.lost == 502 - 9 - 1
    assert tr.counters.jumps_confirmed == 1 and tr.counters.held == 0


def test_a_confirmed_chain_whose_sequence_went_back_is_a_restart_not_a_negative_gap():
    """Seq back while Tms is not (a simulator restarted with another clock origin): a restart once confirmed,
    never a gap with a negative number of lost frames."""
    tr = StreamTracker(max_jump=250, restart_confirm=3)
    for s in range(101):
        tr.offer(s, 4000 + (s - 100) * 40, float(s))
    events = [tr.offer(s, 5000 + (s - 50) * 40, 200.0 + s) for s in (50, 51, 52)]
    assert events[-1].verdict is Verdict.RESTART
    assert tr.counters.lost == 0 and tr.counters.restarts == 1


def test_a_single_restart_like_frame_does_not_restart_the_stream():
    tr = StreamTracker()
    for s in range(100):
        tr.offer(s, (s + 1) * 40, float(s))
    assert tr.offer(0, 40, 200.0).verdict is Verdict.HELD  # forged, or the first of a restart: wait
    assert tr.offer(100, 4040, 200.1).verdict is Verdict.NEXT  # the stream goes on: it was forged
    assert tr.counters.restarts == 0


def test_impossible_encoder_counts_are_rejected():
    tr = StreamTracker(max_ticks_per_s=3000.0)  # 120 ticks per 40 ms cycle at most
    tr.offer(0, 40, 0.0, totals=(0, 0))
    assert tr.offer(1, 80, 0.04, totals=(100, -100)).verdict is Verdict.NEXT
    e = tr.offer(2, 120, 0.08, totals=(100 + 500, -100))
    assert e.verdict is Verdict.IMPLAUSIBLE and tr.last_seq == 1
    assert tr.offer(2, 120, 0.09, totals=(150, -150)).verdict is Verdict.NEXT  # the real one still counts
    assert tr.offer(10, 440, 0.5, totals=(150 + 900, -150)).verdict is Verdict.GAP  # 8 cycles: plausible
    assert tr.counters.implausible == 1


def test_source_gate_binds_the_first_consistent_sender_only():
    g = SourceGate(takeover_after=2.0, confirm=3)
    assert g.candidate(OTHER, 7, 999, "x", 0.0) is None  # a lone datagram never binds
    assert g.candidate(SIM, 0, 40, "a", 0.1) is None
    assert g.candidate(SIM, 1, 80, "b", 0.14) is None
    assert g.candidate(SIM, 2, 120, "c", 0.18) == ["a", "b", "c"]
    assert g.bound == SIM and g.takeovers == 0
    assert not g.open_to(OTHER, 1.0) and g.open_to(SIM, 1.0)
    g.seen(1.0)
    assert not g.open_to(OTHER, 2.9)
    assert g.open_to(OTHER, 3.1)  # silent for more than 2 s: another sender may take over
    for i in range(3):
        g.count_foreign(("127.0.0.1", 50000 + i))
    assert g.foreign_total == 3 and g.foreign["127.0.0.1:50001"] == 1


def test_a_sender_with_another_control_period_is_named_not_bound():
    g = SourceGate(confirm=3, period_ms=40)
    for s in range(5):
        assert g.candidate(SIM, s, (s + 1) * 20, s, 0.02 * s) is None  # a 20 ms script period
    assert g.bound is None and g.period_mismatch == (SIM, 20.0)


def test_a_configured_source_never_changes():
    g = SourceGate(source=SIM)
    assert not g.open_to(OTHER, 100.0)
    assert g.candidate(OTHER, 0, 40, 1, 0.0) is None and g.candidate(OTHER, 1, 80, 2, 0.0) is None
    assert g.candidate(OTHER, 2, 120, 3, 0.0) is None and g.bound == SIM


def test_health_says_what_to_check():
    g = SourceGate()
    assert stream_health({}, {}, None, g, 9810, 0.5, 2.0)[0] == WARN
    g.bound = SIM
    before = {"accepted": 100, "rejected_foreign_source": 0, "held": 0}
    g.count_foreign(OTHER)
    lvl, text = stream_health({"accepted": 125, "rejected_foreign_source": 40, "held": 2}, before, 0.05, g, 9810,
                              0.5, 2.0)
    assert lvl == WARN and "127.0.0.1:40001" in text and "own port" in text and "forged" in text
    assert stream_health({"accepted": 150}, {"accepted": 125}, 0.05, g, 9810, 0.5, 2.0) == (
        OK, "receiving from 127.0.0.1:9808")
    assert stream_health({}, {}, 3.0, g, 9810, 0.5, 2.0)[0] == ERROR


# ---- the bridge's datagram path, without a ROS master ---------------------------------------------------------

class FakeSock:
    def __init__(self):
        self.sent = []

    def sendto(self, data, addr):
        self.sent.append((Command.decode(data), addr))


class LogNode:
    """The little of a middleware node that frame handling uses: its log lines."""

    name = "/raf_bridge"

    def __init__(self):
        self.lines = []

    def log(self, level, text, throttle=0.0):
        self.lines.append((level, text))

    def info(self, text):
        self.log("info", text)

    def warn(self, text, throttle=0.0):
        self.log("warn", text)

    def error(self, text):
        self.log("error", text)

    def ok(self):
        return True


@pytest.fixture
def bridge(field):
    from robotatfactory.ros.bridge_node import Bridge
    from robotatfactory.ros.config import load_config

    b = Bridge(load_config({"camera": {"enabled": False}, "lidar": {"enabled": False},
                            "stream": {"takeover_after": 2.0}}), LogNode(), field=field)
    b.sock = FakeSock()
    b.bound_port = 9810
    b.published = []
    b.publish_frame = lambda f, arrival=None: b.published.append((f.seq, f.time_ms))
    return b


def feed(b, addr, seqs, t0=0.0, tms=None, totals=None):
    for i, s in enumerate(seqs):
        b.handle_datagram(frame(s, tms, totals).encode(), addr, t0 + 0.04 * i)


def test_bridge_binds_the_first_sender_and_ignores_a_second_one(bridge):
    b = bridge
    feed(b, SIM, range(5))
    assert b.gate.bound == SIM
    assert [p[0] for p in b.published] == [0, 1, 2, 3, 4]  # the chain that bound it is published, in order
    assert any(lv == "info" and "stream bound to" in t for lv, t in b.node.lines), b.node.lines
    n_pub, n_sent = len(b.published), len(b.sock.sent)
    feed(b, OTHER, range(100, 110), t0=0.3)  # a second simulator on the same port, a consistent stream
    feed(b, SIM, range(5, 8), t0=0.5)
    assert [p[0] for p in b.published[n_pub:]] == [5, 6, 7]  # nothing of the other sender reached odom/clock
    assert all(addr == SIM for _, addr in b.sock.sent[n_sent:])  # nor a reply
    assert b.gate.foreign["127.0.0.1:40001"] == 10 and b.tracker.counters.rejected["foreign_source"] == 10
    assert b.tracker.counters.restarts == 0


def test_bridge_holds_a_forged_far_future_frame_from_the_bound_source(bridge):
    b = bridge
    feed(b, SIM, range(10))
    clock_before = b.clock.time_ms
    b.handle_datagram(frame(10 ** 9, 10 ** 9).encode(), SIM, 0.5)
    b.handle_datagram(frame(11, totals=(10 ** 6, 0)).encode(), SIM, 0.52)  # impossible ticks
    assert b.clock.time_ms == clock_before and b.published[-1][0] == 9
    assert b.sock.sent[-1][0].seq == 11 and b.sock.sent[-1][1] == SIM  # answered (lockstep never stalls)
    feed(b, SIM, range(10, 13), t0=0.6)
    assert [p[0] for p in b.published[-3:]] == [10, 11, 12]
    c = b.tracker.counters
    assert c.held == 1 and c.implausible == 1 and c.restarts == 0


def test_bridge_restart_from_the_bound_source(bridge):
    b = bridge
    feed(b, SIM, range(200))
    feed(b, SIM, range(0, 5), t0=10.0)  # the simulator restarted on the same source
    assert b.tracker.counters.restarts == 1
    assert b.published[-1] == (4, 200) and b.tracker.last_seq == 4
    assert b.clock.time_ms == 200  # the clock went back only once the restart was confirmed


def test_bridge_new_source_takes_over_only_after_silence(bridge):
    b = bridge
    feed(b, SIM, range(50))  # last frame at t = 1.96
    feed(b, OTHER, range(3), t0=3.0)  # 1 s of silence: not enough
    assert b.gate.bound == SIM and b.gate.takeovers == 0
    feed(b, OTHER, range(3, 8), t0=4.5)  # 2.5 s of silence: taken over by a consistent stream
    assert b.gate.bound == OTHER and b.gate.takeovers == 1
    assert [p[0] for p in b.published[-5:]] == [3, 4, 5, 6, 7]
    n = len(b.published)
    feed(b, SIM, range(50, 53), t0=5.0)  # the old sender is now the foreign one
    assert len(b.published) == n and b.gate.foreign["127.0.0.1:9808"] == 3


# ---- loopback defaults ---------------------------------------------------------------------------------------

def test_every_socket_listens_on_loopback_by_default():
    import argparse

    from robotatfactory.commands import server as server_cmd
    from robotatfactory.commands import sim as sim_cmd
    from robotatfactory.ros.config import load_config
    from robotatfactory.sim.runner import RunnerConfig

    assert load_config().bind_host == "127.0.0.1"
    assert load_config({"simulator": {"host": "192.168.1.20"}}).bind_host == "0.0.0.0"  # SimTwo elsewhere: one flag
    assert load_config({"udp": {"bind_host": "192.168.1.5"}, "simulator": {"host": "*"}}).bind_host == "192.168.1.5"
    assert load_config().camera.endpoint.startswith("tcp://127.0.0.1:")
    rc = RunnerConfig()
    assert rc.host == "127.0.0.1" and rc.server_host == "127.0.0.1" and rc.camera_bind.startswith("tcp://127.0.0.1:")
    for mod in (sim_cmd, server_cmd):
        p = argparse.ArgumentParser()
        mod.add_arguments(p)
        assert p.parse_args([]).host == "127.0.0.1"


def test_the_bridge_yaml_keeps_loopback():
    import yaml

    from robotatfactory.ros.config import load_config

    root = Path(__file__).resolve().parents[1]
    tree = yaml.safe_load((root / "config" / "bridge.yaml").read_text())
    assert load_config(tree).bind_host == "127.0.0.1"


# ---- raf sim's command port ------------------------------------------------------------------------------------

def test_sim_takes_commands_from_one_controller(field, robot):
    from robotatfactory.sim import SimConfig, Simulator
    from robotatfactory.sim.runner import RunnerConfig, SimRunner

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.settimeout(0.2)
    controller = sink.getsockname()
    rogue = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rogue.bind(("127.0.0.1", 0))
    sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, start_pose=(-0.6, -0.38, 0.0)))
    runner = SimRunner(sim, RunnerConfig(port=0, bridge=sink.getsockname(), camera_bind=None, server_port=None,
                                         mode="realtime", duration=1.2, quiet=True, command_timeout=0.5))
    box = {}
    runner.open()
    th = threading.Thread(target=lambda: box.setdefault("r", runner.run()), daemon=True)
    th.start()
    n = 0
    try:
        while th.is_alive():
            try:
                data, addr = sink.recvfrom(65535)
            except socket.timeout:
                continue
            f = SensorFrame.decode(data)
            n += 1
            if n <= 10:  # the controller drives for 10 cycles, then falls silent
                sink.sendto(Command(0.2, 0.0, False, f.seq).encode(), addr)
            rogue.sendto(Command(-0.5, 1.0, True, f.seq).encode(), addr)  # never obeyed
    finally:
        th.join(10)
        sink.close()
        rogue.close()
    c = box["r"].counters
    assert c["foreign_source"] >= 25 and c["commands"] == 10
    assert c["command_timeouts"] == 1  # stopped 0.5 s (simulation) after the last command
    assert runner.command.v == 0.0 and not runner.command.magnet
    assert runner.controller == controller


def test_nodes_listen_on_loopback_when_the_master_is_local(monkeypatch):
    from robotatfactory.ros.mw.ros1 import loopback_ros_default

    for uri, ros_ip, expect in (("http://127.0.0.1:11311/", None, "127.0.0.1"),
                                ("http://localhost:11311/", None, "127.0.0.1"),
                                ("http://192.168.1.20:11311/", None, None),  # a master elsewhere: untouched
                                ("http://127.0.0.1:11311/", "10.0.0.5", "10.0.0.5")):  # the user's choice wins
        monkeypatch.setenv("ROS_MASTER_URI", uri)
        monkeypatch.delenv("ROS_HOSTNAME", raising=False)
        if ros_ip is None:
            monkeypatch.delenv("ROS_IP", raising=False)
        else:
            monkeypatch.setenv("ROS_IP", ros_ip)
        loopback_ros_default()
        import os

        assert os.environ.get("ROS_IP") == expect
