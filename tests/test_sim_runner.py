"""``SimRunner`` and ``raf sim``: the UDP endpoints with bad input, the lockstep timeout policy, the camera
stream, the factory-state server and the command line."""
import socket
import subprocess
import threading
import time

import pytest

from robotatfactory.sim import SimConfig
from robotatfactory.sim.runner import RunnerConfig, SimRunner
from robotatfactory.simtwo import Command, SensorFrame


@pytest.fixture
def bridge():
    """A UDP socket playing the bridge, on a free loopback port."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(0.2)
    yield s
    s.close()


def make_runner(field, robot, bridge, **kw):
    from robotatfactory.sim import Simulator

    sim_kw = kw.pop("sim", {})
    sim_kw.setdefault("camera", False)
    sim_kw.setdefault("lidar", False)
    sim = Simulator(field, robot, SimConfig(**sim_kw))
    cfg = dict(port=0, bridge=bridge.getsockname(), camera_bind=None, server_port=None, mode="fast", quiet=True)
    cfg.update(kw)
    return SimRunner(sim, RunnerConfig(**cfg))


def frames_from(bridge, thread, limit=20.0):
    """Yield (SensorFrame, sender) as they arrive until the runner's thread ends."""
    t0 = time.monotonic()
    while thread.is_alive() and time.monotonic() - t0 < limit:
        try:
            data, addr = bridge.recvfrom(65535)
        except socket.timeout:
            continue
        yield SensorFrame.decode(data), addr


def run_in_thread(runner):
    box = {}
    t = threading.Thread(target=lambda: box.setdefault("result", runner.run()), daemon=True)
    runner.open()
    t.start()
    return t, box


def test_bad_command_datagrams_are_counted_and_the_last_valid_command_kept(field, robot, bridge):
    # the command timeout off (raf sim --command-timeout 0): the one valid command must last the whole run
    runner = make_runner(field, robot, bridge, mode="realtime", duration=1.6, sim={"start_pose": (-0.6, -0.38, 0.0)},
                         command_timeout=None)
    t, box = run_in_thread(runner)
    bad = [b"hello", b"RAF\r\n1\r\n\r\nV\r\nfast\r\n\r\n", b"RAF\r\n2\r\n\r\nV\r\n0\r\n\r\nW\r\n0\r\n\r\nS\r\n0\r\n\r\n",
           b"\xff\xfe\x00", b"RAF\r\n1\r\n\r\nSeq\r\n3\r\n\r\nV\r\ninf\r\n\r\nW\r\n0\r\n\r\nS\r\n0\r\n\r\n", b""]
    frames = 0
    for f, addr in frames_from(bridge, t):
        frames += 1
        if frames == 3:
            bridge.sendto(Command(0.2, 0.0, False, f.seq).encode(), addr)
        if 5 <= frames < 5 + len(bad):
            bridge.sendto(bad[frames - 5], addr)
    t.join(10)
    r = box["result"]
    c = r.counters
    assert r.reason == "duration" and r.sim_time == pytest.approx(1.6)
    assert c["commands"] == 1
    assert c["rejected"] == len(bad)
    assert c["foreign"] >= 2 and c["version"] == 1 and c["malformed"] >= 2
    assert c["frames_sent"] == frames == 40
    # the robot kept driving with the last valid command through all of it
    assert runner.sim.command.v == 0.2
    assert runner.sim.pose[0] > -0.6 + 0.2


def test_latest_valid_command_wins(field, robot, bridge):
    runner = make_runner(field, robot, bridge, duration=0.4, lockstep=True, lockstep_timeout=2.0)
    t, box = run_in_thread(runner)
    for f, addr in frames_from(bridge, t):
        # an unsolicited command, then the reply: the reply arrives last and wins
        bridge.sendto(Command(0.5, 0.5, True, -1).encode(), addr)
        bridge.sendto(Command(0.1, -0.2, False, f.seq).encode(), addr)
    t.join(10)
    r = box["result"]
    assert r.counters["replies"] == 10 and r.counters["timeouts"] == 0
    assert runner.command == Command(0.1, -0.2, False, 9)  # the reply to the last frame
    assert runner.sim.command == Command(0.1, -0.2, False, 8)  # what the last cycle ran with


@pytest.mark.parametrize("policy", ["stop", "hold", "exit"])
def test_lockstep_timeout_policy(field, robot, bridge, policy):
    """The controller answers 10 frames with V = 0.3 and the magnet on, then falls silent (the command timeout off:
    the lockstep policy alone decides)."""
    runner = make_runner(field, robot, bridge, duration=2.0, lockstep=True, lockstep_timeout=0.05, on_timeout=policy,
                         sim={"start_pose": (-0.7, -0.38, 0.0)}, command_timeout=None)
    t, box = run_in_thread(runner)
    answered = 0
    for f, addr in frames_from(bridge, t):
        if answered < 10:
            bridge.sendto(Command(0.3, 0.0, True, f.seq).encode(), addr)
            answered += 1
    t.join(20)
    assert not t.is_alive()  # never a hang
    r = box["result"]
    c = r.counters
    if policy == "exit":
        assert r.reason == "timeout-exit" and r.exit_code == 3
        assert c["timeouts"] == 1 and c["frames_sent"] == 11
        return
    assert r.reason == "duration" and c["timeouts"] == 50 - 10 and c["replies"] == 10
    v, _ = runner.sim.body_velocity
    if policy == "stop":
        assert runner.sim.command.v == 0.0 and runner.sim.command.magnet  # stopped, magnet kept
        assert abs(v) < 0.005
    else:
        assert runner.sim.command.v == 0.3
        assert v == pytest.approx(0.3, abs=0.03)  # instantaneous: SimTwo's PID leaves a ripple within each cycle


@pytest.mark.render
def test_camera_frames_are_published_raw(field, robot, bridge):
    import zmq

    from robotatfactory.simtwo import decode_frame

    ctx = zmq.Context()
    probe = ctx.socket(zmq.PUB)
    port = probe.bind_to_random_port("tcp://127.0.0.1")
    probe.close(0)
    endpoint = f"tcp://127.0.0.1:{port}"
    runner = make_runner(field, robot, bridge, mode="realtime", duration=2.0, camera_bind=endpoint,
                         sim={"camera": True, "camera_timing": "grid"})
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.SUBSCRIBE, b"")
    sub.setsockopt(zmq.RCVTIMEO, 200)
    t, box = run_in_thread(runner)
    sub.connect(endpoint)
    msgs = []
    while t.is_alive() or sub.poll(0):
        try:
            msgs.append(sub.recv(copy=True))
        except zmq.Again:
            continue
    t.join(10)
    sub.close(0)
    ctx.term()
    assert box["result"].counters["camera_frames"] == 31  # t = 0 .. 2.0 s at 15 frames/s
    assert len(msgs) >= 10  # a late subscriber misses the first ones (PUB/SUB), not the rest
    assert all(len(m) == 640 * 480 * 4 for m in msgs)
    img = decode_frame(msgs[-1])
    assert img.shape == (480, 640, 3) and img.std() > 10


def test_factory_server_answers_from_the_simulation(field, robot, bridge):
    from robotatfactory.competition import query

    runner = make_runner(field, robot, bridge, mode="realtime", duration=2.0, server_port=0,
                         sim={"competition": True, "round_no": 3, "parts": "RGBX", "start_after": 0.6})
    t, box = run_in_thread(runner)
    host, port = runner.server.address
    assert query("IWP", host, port) == "STOP"  # before the run starts
    assert query("PING", host, port) == "PONG"
    deadline = time.monotonic() + 10
    while runner.sim.time < 0.8 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert query("IWP", host, port) == "RGBX"
    assert query("MAP", host, port) == "XXXX"
    assert query("CTL", host, port).startswith("T")
    assert query("hello", host, port).startswith("ERR")
    t.join(10)
    assert "score" in runner.status_line(1.0)
    assert box["result"].report.round_no == 3


def test_raf_sim_runs_and_prints_the_score(raf_cmd, tmp_path):
    def free_port():
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    p = subprocess.run(raf_cmd + ["sim", "--duration", "1.2", "--no-camera", "--port", str(free_port()),
                                  "--server-port", str(free_port()), "--bridge", f"127.0.0.1:{free_port()}",
                                  "--status-every", "0.3", "--round", "2", "--seed", "3"],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "duration at t = 1.20 s" in p.stdout
    assert "Round 2, incoming" in p.stdout and "total: 0 of" in p.stdout
    assert "factory counters: processed 0, cancelled 0, teleports_late 0" in p.stdout
    assert "rtf" in p.stdout  # the status line


@pytest.mark.render
def test_raf_sim_snapshot_writes_an_overview(raf_cmd, tmp_path):
    import cv2

    out = tmp_path / "field.png"
    p = subprocess.run(raf_cmd + ["sim", "--snapshot", str(out)], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    img = cv2.imread(str(out))
    assert img is not None and img.shape == (960, 1280, 3)
    # the printed floor (light) covers a good part of the picture, the ground around it is darker
    light = (img.mean(axis=2) > 200).mean()
    assert 0.2 < light < 0.9


def test_bad_settings_are_clear_errors(raf_cmd):
    p = subprocess.run(raf_cmd + ["sim", "--start-pose", "1,2", "--snapshot", "x.png"], capture_output=True,
                       text=True, timeout=60)
    assert p.returncode == 2 and "x,y,theta" in p.stderr and "Traceback" not in p.stderr
    p = subprocess.run(raf_cmd + ["sim", "--bridge", "localhost:http"], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "numeric port" in p.stderr


def test_cached_frame_encoder_gives_the_codecs_bytes(field, robot):
    from robotatfactory.sim import Simulator
    from robotatfactory.sim.runner import CachedFrameEncoder

    sim = Simulator(field, robot, SimConfig(camera=False, lidar=True, beacons=True, seed=2))
    enc = CachedFrameEncoder()
    for i in range(30):
        f = sim.step_cycle(Command(0.2, 1.0 if i < 15 else -2.0, False))
        assert enc.encode(f) == f.encode()
    f.ranges[[0, 5, 359]] = [-1.0, 1e-5, 123456.7]  # no return, exponent and rounding formats
    assert enc.encode(f) == f.encode()
    assert len(f.parts) == 4 and b"PartsN\r\n4\r\n" in enc.encode(f)  # the round's parts, as control.pas sends
    f.camera_frames = 7  # a paced run's optional CamN label
    assert enc.encode(f) == f.encode() and b"CamN\r\n7\r\n" in f.encode()
    assert SensorFrame.decode(f.encode()).camera_frames == 7
    f.camera_frames = None
    assert b"CamN" not in enc.encode(f) and SensorFrame.decode(f.encode()).camera_frames is None
    sim.close()


def test_replies_are_read_only_between_gui_turns_and_the_first_wins(field, robot, bridge):
    """reply_timing simtwo: a script call in the same GUI turn as the previous one reads nothing (the replies
    wait), and of the replies read together the first is applied (SimTwo's ReadUDPData + control.pas)."""
    from robotatfactory.sim import Simulator
    from robotatfactory.sim.camera import GuiIteration

    sim = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False))
    # turns: steps 1-40, a catch-up turn 41-120 (the calls before steps 41 and 81 both in it), then 121-160
    sim._turns = iter([GuiIteration(0.0, 0, 40, 0.0, None), GuiIteration(0.0, 40, 80, 0.0, None),
                       GuiIteration(0.0, 120, 40, 0.0, None), GuiIteration(0.0, 160, 40, 0.0, None)])
    got = []
    for _ in range(4):
        got.append(sim.replies_readable())
        sim.step_cycle(Command(0.0, 0.0, False))
    assert got == [True, True, False, True]
    every = Simulator(field, robot, SimConfig(camera=False, lidar=False, competition=False,
                                              reply_timing="every_cycle"))
    assert all(every.replies_readable() for _ in range(5))

    runner = make_runner(field, robot, bridge)
    runner.open()
    runner._frame_seq = 9  # (as if frames 0-9 had been sent)
    try:
        for v, seq in ((0.1, 5), (0.2, 6), (0.3, 7)):
            bridge.sendto(Command(v, 0.0, False, seq).encode(), runner.address)
        time.sleep(0.2)
        runner._drain(first_wins=True)
        c = runner.counters
        assert runner.command.v == 0.1 and (c.commands, c.applied, c.superseded) == (3, 1, 2)
        for v, seq in ((0.4, 6), (0.5, 7)):
            bridge.sendto(Command(v, 0.0, False, seq).encode(), runner.address)
        time.sleep(0.2)
        runner._drain()  # every_cycle: the newest wins
        assert runner.command.v == 0.5 and (c.applied, c.superseded) == (2, 3)
    finally:
        runner.close()


@pytest.mark.parametrize("first_wins", [True, False])
def test_a_reply_acts_only_if_its_seq_is_acceptable(field, robot, bridge, first_wins):
    """control.pas's SeqAcceptable, in every mode: a reply acts if its Seq is -1 or newer than the last one
    applied and not newer than the frame just sent. A duplicate, a reply held back behind a newer one and one
    to a frame not sent yet never act; with SimTwo's reply timing an unacceptable first reply of a script call
    spoils the call (control.pas reads the first occurrence of each label)."""
    runner = make_runner(field, robot, bridge)
    runner.open()
    runner._frame_seq = 9  # (as if frames 0-9 had been sent)

    def read(*cmds):
        for v, seq in cmds:
            bridge.sendto(Command(v, 0.0, False, seq).encode(), runner.address)
        time.sleep(0.2)
        runner._drain(first_wins=first_wins)
        return runner.command.v

    try:
        c = runner.counters
        assert read((0.1, 5)) == 0.1
        assert read((0.2, 5)) == 0.1 and c.stale == 1  # a duplicate
        assert read((0.3, 4)) == 0.1 and c.stale == 2  # held back behind a newer one
        assert read((0.4, 10)) == 0.1 and c.stale == 3  # a frame not sent yet
        assert read((0.0, -1)) == 0.0  # unsolicited (a watchdog's stop): acts, and Seq 6 still may
        assert read((0.3, 3), (0.6, 6)) == (0.0 if first_wins else 0.6)
        assert read((0.7, 7)) == 0.7 and c.applied == (3 if first_wins else 4)
    finally:
        runner.close()


def test_a_frame_answered_twice_counts_once(field, robot, bridge):
    """``replies`` counts frames answered: the awaited reply and its duplicate, read in one wait, are one."""
    runner = make_runner(field, robot, bridge)
    runner.open()
    runner._frame_seq = 4
    try:
        for _ in range(2):
            bridge.sendto(Command(0.1, 0.0, False, 4).encode(), runner.address)
        time.sleep(0.2)
        assert runner._drain(expect_seq=4)
        c = runner.counters
        assert c.commands == 2 and c.replies == 1 and c.stale == 1
    finally:
        runner.close()


def test_reply_timing_is_checked():
    from robotatfactory.errors import ConfigError

    with pytest.raises(ConfigError, match="reply_timing"):
        SimConfig(reply_timing="sometimes")
