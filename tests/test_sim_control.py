"""The stand-in's control channel (sim/control.py) through a running ``SimRunner``: every request, bad requests,
and determinism (the same seed and commands in lockstep give the same SensorFrames, byte for byte, after a
reset as after a fresh start)."""
import json
import math
import socket
import threading
import time

import pytest

from robotatfactory.sim import SimConfig
from robotatfactory.sim.runner import RunnerConfig, SimRunner
from robotatfactory.simtwo import Command


def request(addr, req, timeout=10.0):
    """One request (dict or raw bytes) to the control channel; its JSON reply."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.settimeout(timeout)
    try:
        s.sendto(req if isinstance(req, bytes) else json.dumps(req).encode(), addr)
        return json.loads(s.recvfrom(65535)[0])
    finally:
        s.close()


class Controller:
    """Plays the bridge in lockstep: records every SensorFrame datagram and answers it with a Command
    that depends on its Seq only (``drive(seq) -> (v, w)``)."""

    def __init__(self, drive):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.drive = drive
        self.frames: list[bytes] = []
        self._run = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        from robotatfactory.simtwo import SensorFrame

        while self._run:
            try:
                data, addr = self.sock.recvfrom(65535)
            except socket.timeout:
                continue
            f = SensorFrame.decode(data)
            self.frames.append(data)
            self.answer(f, addr)

    def answer(self, f, addr) -> None:
        """Reply to frame ``f`` (a subclass may answer otherwise)."""
        v, w = self.drive(f.seq)
        self.sock.sendto(Command(v, w, False, f.seq).encode(), addr)

    def take(self) -> list[bytes]:
        out, self.frames = self.frames, []
        return out

    def close(self):
        self._run = False
        self.thread.join(2)
        self.sock.close()


def start(field, robot, bridge_addr, sim=None, **kw):
    from robotatfactory.sim import Simulator

    sim_kw = dict(camera=False, lidar=True)
    sim_kw.update(sim or {})
    cfg = dict(port=0, bridge=bridge_addr, camera_bind=None, server_port=None, mode="fast", quiet=True,
               control_port=0)
    cfg.update(kw)
    runner = SimRunner(Simulator(field, robot, SimConfig(**sim_kw)), RunnerConfig(**cfg))
    runner.open()
    box = {}
    t = threading.Thread(target=lambda: box.setdefault("result", runner.run()), daemon=True)
    t.start()
    return runner, t, box


def stop(runner, t):
    runner.request_stop()
    t.join(10)
    assert not t.is_alive()


def test_every_request_and_bad_requests(field, robot):
    ctl_peer = Controller(lambda seq: (0.0, 0.0))
    runner, t, box = start(field, robot, ctl_peer.sock.getsockname(), start_paused=True)
    addr = runner.control_address
    try:
        st = request(addr, {"op": "get_state", "id": 1})
        assert st["ok"] and st["id"] == 1 and st["paused"] and st["seq"] == 0 and st["time"] == 0.0
        assert set(st["ops"]) >= {"reset", "pause", "resume", "step", "set_robot_pose", "place_part",
                                  "remove_part", "get_state"}
        parts = {p["id"]: p for p in st["parts"]}
        assert len(parts) >= 1
        time.sleep(0.3)
        assert runner.sim.seq == 0  # paused: no cycle runs
        # step N: the reply comes after N cycles
        r = request(addr, {"op": "step", "cycles": 5, "id": "a"})
        assert r["ok"] and r["id"] == "a" and r["seq"] == 5 and abs(r["time"] - 0.2) < 1e-9
        # the 5 frames were sent before the reply; the peer's thread may still be decoding them
        end = time.monotonic() + 5.0
        while len(ctl_peer.frames) < 5 and time.monotonic() < end:
            time.sleep(0.01)
        assert len(ctl_peer.take()) == 5
        # teleport
        r = request(addr, {"op": "set_robot_pose", "x": 0.3, "y": -0.2, "theta": 4.0})
        assert r["ok"] and r["pose"][:2] == pytest.approx([0.3, -0.2], abs=1e-9)
        assert r["pose"][2] == pytest.approx(math.remainder(4.0, 2 * math.pi), abs=1e-9)
        request(addr, {"op": "step", "cycles": 3})
        x, y, th = runner.sim.pose
        assert (x, y) == pytest.approx((0.3, -0.2), abs=0.005)
        # parts: in a slot, at a pose, removed
        pid = min(parts)
        slot = next(s for s in field.slots if s.zone == "outgoing")
        r = request(addr, {"op": "place_part", "part": pid, "slot": slot.name, "type": "B"})
        assert r["ok"] and r["part_pose"][:2] == pytest.approx(list(slot.xy), abs=1e-9)
        request(addr, {"op": "step", "cycles": 2})
        st = request(addr, {"op": "get_state"})
        p = next(p for p in st["parts"] if p["id"] == pid)
        assert p["type"] == "B" and p["pose"][:2] == pytest.approx(list(slot.xy), abs=0.01)
        r = request(addr, {"op": "place_part", "part": pid, "x": 0.0, "y": 0.5, "facing": 1.0})
        assert r["ok"] and r["part_pose"] == pytest.approx([0.0, 0.5, 1.0], abs=1e-9)
        r = request(addr, {"op": "remove_part", "part": pid})
        assert r["ok"]
        st = request(addr, {"op": "get_state"})
        p = next(p for p in st["parts"] if p["id"] == pid)
        assert p["removed"] and not field.floor.contains(*p["pose"][:2])
        # bad requests: a specific error each, the scene untouched
        before = (runner.sim.seq, runner.sim.pose)
        bad = [(b"\xff\x00", "bad_request"), (b"[1, 2]", "bad_request"), (b"{", "bad_request"),
               ({"op": "fly"}, "unknown_op"), ({"id": 3}, "unknown_op"),
               ({"op": "step", "cycles": 0}, "bad_argument"), ({"op": "step", "cycles": "5"}, "bad_argument"),
               ({"op": "set_robot_pose", "x": 0.0}, "bad_argument"),
               (b'{"op": "set_robot_pose", "x": NaN, "y": 0}', "bad_argument"),  # Python's json reads NaN
               ({"op": "set_robot_pose", "x": 50.0, "y": 0.0}, "out_of_field"),
               ({"op": "place_part", "part": 999, "slot": slot.name}, "unknown_part"),
               ({"op": "place_part", "part": pid, "slot": "garage_1"}, "unknown_slot"),
               ({"op": "place_part", "part": pid, "slot": slot.name, "type": "Q"}, "bad_argument"),
               ({"op": "reset", "round": 7}, "bad_argument"), ({"op": "reset", "parts": "RGQ"}, "bad_argument"),
               ({"op": "reset", "start_pose": [9, 9, 0]}, "out_of_field")]
        for req, code in bad:
            r = request(addr, req)
            assert not r["ok"] and r["error"] == code, (req, r)
            assert r["message"]
        assert (runner.sim.seq, runner.sim.pose) == before
        # resume runs on; step while running is refused; pause stops it
        r = request(addr, {"op": "resume"})
        assert r["ok"] and not r["paused"]
        time.sleep(0.3)
        assert runner.sim.seq > before[0] + 3
        r = request(addr, {"op": "step", "cycles": 2})
        assert not r["ok"] and r["error"] == "not_paused"
        r = request(addr, {"op": "pause"})
        assert r["ok"] and r["paused"]
        seq = runner.sim.seq
        time.sleep(0.3)
        assert runner.sim.seq == seq
        # while a step runs, a reset or a second step is refused (busy); the step's reply comes after its cycles
        long_step = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        long_step.settimeout(30)
        long_step.sendto(json.dumps({"op": "step", "cycles": 400, "id": "long"}).encode(), addr)
        wait_for = time.monotonic() + 5
        while runner.control.steps_left == 0 and time.monotonic() < wait_for:
            time.sleep(0.001)
        r = request(addr, {"op": "reset"})
        assert not r["ok"] and r["error"] == "busy"
        r = json.loads(long_step.recvfrom(65535)[0])
        long_step.close()
        assert r["ok"] and r["id"] == "long" and r["seq"] == seq + 400
        # reset: a new round and layout, Seq and time from zero
        r = request(addr, {"op": "reset", "round": 2, "parts": "RXGB", "seed": 4})
        assert r["ok"] and r["seq"] == 0 and r["time"] == 0.0 and r["round"] == 2 and r["seed"] == 4
        assert sorted(p["type"] for p in r["parts"]) == ["B", "G", "R"] and not any(p["removed"] for p in r["parts"])
        assert r["pose"][:2] == pytest.approx([field.start_pose.x, field.start_pose.y], abs=0.01)
        assert runner.control.errors == len(bad) + 2
    finally:
        stop(runner, t)
        ctl_peer.close()
    assert box["result"].reason == "stopped"


def drive_a(seq):
    return 0.25 if seq < 20 else 0.1, 0.8 * math.sin(seq / 7)


def test_frames_after_a_reset_equal_a_fresh_start_byte_for_byte(field, robot):
    """Lockstep, the same seed and commands: a fresh start, then a reset after other driving, then another
    process-fresh runner all send identical SensorFrame datagrams (LIDAR noise and the round included)."""
    n = 30
    peer = Controller(drive_a)
    runner, t, _ = start(field, robot, peer.sock.getsockname(), start_paused=True, lockstep=True,
                         lockstep_timeout=5.0, sim={"seed": 11})
    addr = runner.control_address
    try:
        assert request(addr, {"op": "step", "cycles": n})["ok"]
        fresh = peer.take()
        peer.drive = lambda seq: (-0.2, 0.5)  # something else in between, with a teleport
        request(addr, {"op": "set_robot_pose", "x": 0.2, "y": 0.1, "theta": 1.0})
        request(addr, {"op": "step", "cycles": 17})
        other = peer.take()
        assert len(other) == 17 and other != fresh[:17]
        peer.drive = drive_a
        assert request(addr, {"op": "reset"})["ok"]
        assert request(addr, {"op": "step", "cycles": n})["ok"]
        after_reset = peer.take()
        # another seed: the same commands give other frames (LIDAR noise); back to 11: the same again
        assert request(addr, {"op": "reset", "seed": 12})["ok"]
        request(addr, {"op": "step", "cycles": n})
        seed12 = peer.take()
        assert request(addr, {"op": "reset", "seed": 11})["ok"]
        request(addr, {"op": "step", "cycles": n})
        again = peer.take()
    finally:
        stop(runner, t)
        peer.close()
    assert len(fresh) == n and after_reset == fresh and again == fresh
    assert seed12 != fresh
    # a new runner, fresh from its constructor, agrees too
    peer = Controller(drive_a)
    runner, t, _ = start(field, robot, peer.sock.getsockname(), start_paused=True, lockstep=True,
                         lockstep_timeout=5.0, sim={"seed": 11})
    try:
        request(runner.control_address, {"op": "step", "cycles": n})
        assert peer.take() == fresh
    finally:
        stop(runner, t)
        peer.close()


def test_raf_sim_prints_the_control_port_and_a_taken_default_is_only_a_warning(raf_cmd):
    import subprocess

    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    p = taken.getsockname()[1]
    base = raf_cmd + ["sim", "--fast", "--duration", "0.1", "--no-camera", "--no-server", "--quiet"]
    try:
        free = subprocess.run(base + ["--port", str(p - 3)], capture_output=True, text=True, timeout=60)
        assert free.returncode == 0 and f"control udp 127.0.0.1:{p + 1}" in free.stdout
        r = subprocess.run(base + ["--port", str(p - 4)], capture_output=True, text=True, timeout=60)
        assert r.returncode == 0 and "running without a control channel" in r.stderr
        assert "control udp" not in r.stdout
        r = subprocess.run(base + ["--port", str(p - 4), "--control-port", str(p)], capture_output=True, text=True,
                           timeout=60)
        assert r.returncode == 2 and "the control channel cannot bind" in r.stderr
    finally:
        taken.close()


def test_raf_simctl_sends_requests_and_reports_refusals(field, robot, raf_cmd):
    import subprocess

    peer = Controller(lambda seq: (0.0, 0.0))
    runner, t, _ = start(field, robot, peer.sock.getsockname(), start_paused=True)
    ctl = "127.0.0.1:%d" % runner.control_address[1]

    def simctl(*args):
        r = subprocess.run(raf_cmd + ["simctl", *args, "--control", ctl], capture_output=True, text=True, timeout=60)
        return r.returncode, (json.loads(r.stdout) if r.stdout.startswith("{") else r.stdout + r.stderr)

    try:
        code, r = simctl("step", "3")
        assert code == 0 and r["seq"] == 3
        code, r = simctl("set_robot_pose", "-0.4", "-0.35", "0.5")
        assert code == 0 and r["pose"] == pytest.approx([-0.4, -0.35, 0.5], abs=1e-9)
        pid = request(runner.control_address, {"op": "get_state"})["parts"][0]["id"]
        code, r = simctl("place_part", str(pid), "--slot", "outgoing_2", "--type", "G")
        assert code == 0 and r["part"] == pid
        code, r = simctl("place_part", str(pid), "--slot", "nowhere")
        assert code == 1 and r["error"] == "unknown_slot"
        code, r = simctl("reset", "--round", "3", "--seed", "2")
        assert code == 0 and r["round"] == 3 and r["seed"] == 2 and r["seq"] == 0
        code, out = simctl("step")
        assert code == 2 and "expected 1 number" in out
    finally:
        stop(runner, t)
        peer.close()
    code, out = simctl("get_state")  # nobody there any more
    assert code == 2 and "no answer" in out


def test_a_reset_frees_the_old_scene(field, robot):
    """A reset's old scene is held only by its own reference cycles: the runner collects it once its loop has
    let go of it, instead of leaving it (about 16 MB each) to Python's rare full collections; the realtime soak
    (issue 22) saw raf sim grow by that much at every round."""
    import gc
    import weakref

    peer = Controller(lambda seq: (0.0, 0.0))
    runner, t, _ = start(field, robot, peer.sock.getsockname())
    try:
        gc.disable()  # only the runner's own collection may free them
        olds = []
        for seed in (1, 2, 3):
            olds.append(weakref.ref(runner.sim))
            r = request(runner.control_address, {"op": "reset", "seed": seed})
            assert r["ok"] and r["seed"] == seed
        end = time.monotonic() + 5.0
        while any(o() is not None for o in olds) and time.monotonic() < end:
            time.sleep(0.02)
        assert [o() is None for o in olds] == [True, True, True]
    finally:
        gc.enable()
        stop(runner, t)
        peer.close()
