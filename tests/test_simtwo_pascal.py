"""The SimTwo side, proven without Windows: simtwo/control.pas compiled UNCHANGED with Free Pascal.

The harness (simtwo/test/harness.pas) includes control.pas and links it against a stand-in of SimTwo's
script API (simtwo/test/simtwo_api.pas) with the same names and signatures; the stand-in returns scripted
sensor values, records every actuator call, and does real UDP on loopback, with ReadUDPData returning
everything received since the previous call, concatenated, as SimTwo does. The test drives the cycles (a
HARNESS-TICK datagram each), decodes every datagram the script sent with the Python codec
(robotatfactory.simtwo.SensorFrame) and answers with Python-encoded Commands, then checks what the script
applied against the protocol's rules (docs/protocol.md, docs/simtwo.md).

Free Pascal's Format and string handling stand in for those SimTwo runs scripts with (SimTwo is itself
built with Free Pascal/Lazarus, and its PascalScript calls the host's Format).
"""
from __future__ import annotations

import configparser
import hashlib
import math
import random
import re
import select
import shutil
import socket
import subprocess
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from robotatfactory.robot import load_robot
from robotatfactory.simtwo import Command, ProtocolError, SensorFrame

REPO = Path(__file__).resolve().parents[1]
SIMTWO = REPO / "simtwo"
CONTROL = SIMTWO / "control.pas"
API = SIMTWO / "test" / "simtwo_api.pas"
HARNESS = SIMTWO / "test" / "harness.pas"
FRAME_LABELS = ["RAF", "Seq", "Tms", "Enc1", "Enc2", "Odo1", "Odo2", "X", "Y", "Theta", "Contact", "Magnet",
                "LidarN", "Lidar"]
TICK = b"HARNESS-TICK"
PERIOD_MS = 40  # the stand-in's ScriptPeriod


# ---- the script's settings, read from the shipped file ---------------------------------------------------

def control_constants() -> dict[str, str]:
    text = CONTROL.read_text()
    const = text[text.index("\nconst") : text.index("\nvar")]
    out = {}
    for m in re.finditer(r"^\s*([A-Z_][A-Z0-9_]*)\s*=\s*([^;]+);", const, re.M):
        out[m.group(1)] = m.group(2).strip()
    return out


CONST = control_constants()
ROBOT = load_robot()


# ---- building the harness -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def harness_exe(tmp_path_factory) -> Path:
    fpc = shutil.which("fpc")
    if fpc is None:
        pytest.fail("fpc not found: the Free Pascal compiler (Debian package fp-compiler, installed by "
                    "scripts/bootstrap.sh) is required to prove simtwo/control.pas")
    # the harness must include the shipped file: nothing called control.pas next to harness.pas
    assert not (HARNESS.parent / "control.pas").exists()
    assert "{$I control.pas}" in HARNESS.read_text()
    before = hashlib.sha256(CONTROL.read_bytes()).hexdigest()
    out = tmp_path_factory.mktemp("fpc")
    cmd = [fpc, "-Mdelphi", "-O1", f"-Fu{HARNESS.parent}", f"-Fi{SIMTWO}", f"-FU{out}", f"-FE{out}",
           f"-o{out / 'harness'}", str(HARNESS)]
    res = subprocess.run(cmd, cwd=out, capture_output=True, text=True, timeout=180)
    assert res.returncode == 0, f"fpc failed:\n{res.stdout}\n{res.stderr}"
    assert "Error" not in res.stdout
    assert hashlib.sha256(CONTROL.read_bytes()).hexdigest() == before
    return out / "harness"


# ---- running it -----------------------------------------------------------------------------------------

@dataclass
class Cycle:
    get: dict = field(default_factory=dict)
    sets: list = field(default_factory=list)
    logs: list = field(default_factory=list)
    duration_ms: int | None = None


@dataclass
class Run:
    frames: list[bytes]
    replies: list[list[bytes]]
    cycles: dict[int, Cycle]
    cfg_default: dict[str, str]
    cfg: dict[str, str]
    record: list[str]

    def applied(self, k: int) -> tuple[float, float, int | None]:
        """(left, right) wheel speed refs (rad/s) and SetSensorVin value set in cycle k (-1: Initialize)."""
        refs, vin = {}, None
        for name, args in self.cycles[k].sets:
            if name == "AxisSpeedRef":
                refs[int(args[0])] = float(args[1])
            elif name == "SensorVin":
                vin = int(args[1])
        return refs[0], refs[1], vin

    def logs(self) -> list[str]:
        return [m for c in self.cycles.values() for m in c.logs]


def parse_record(lines: list[str]) -> tuple[dict[int, Cycle], dict, dict]:
    cycles: dict[int, Cycle] = {}
    cfgs: list[dict] = [{}, {}]
    ncfg = 0
    for line in lines:
        kind, _, rest = line.partition(" ")
        if kind == "CFG":
            key, _, val = rest.partition(" ")
            idx = 0 if key not in cfgs[0] else 1
            cfgs[idx][key] = val
            ncfg += 1
            continue
        if kind not in ("GET", "SET", "LOG", "CYCLE"):
            continue
        k_s, _, rest = rest.partition(" ")
        c = cycles.setdefault(int(k_s), Cycle())
        if kind == "GET":
            parts = rest.split(" ")
            name = parts[0]
            if name == "SensorValues":
                c.get.setdefault(name, {})[int(parts[1])] = [float(v) for v in parts[3].split(";")]
            elif name in ("AxisOdo", "SensorVal"):
                c.get.setdefault(name, {})[int(parts[1])] = float(parts[2])
            else:
                c.get[name] = parts[1:]
        elif kind == "SET":
            parts = rest.split(" ")
            c.sets.append((parts[0], parts[1:]))
        elif kind == "LOG":
            c.logs.append(rest)
        elif kind == "CYCLE":
            parts = rest.split(" ")
            if parts[0] == "END":
                c.duration_ms = int(parts[1])
    return cycles, cfgs[0], cfgs[1]


def run_harness(exe: Path, tmp_path: Path, cycles: int, policy, *, frame_timeout: float = 10.0,
                **opts) -> Run:
    """Runs the harness for `cycles` cycles; policy(k, raw_frame) -> list of reply datagrams."""
    rec = tmp_path / f"record_{time.monotonic_ns()}.txt"
    bridge = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    bridge.bind(("127.0.0.1", 0))
    bridge.settimeout(frame_timeout)
    args = [str(exe), f"record={rec}", f"cycles={cycles}", f"bridge_port={bridge.getsockname()[1]}",
            "bridge_ip=127.0.0.1"] + [f"{k}={v}" for k, v in opts.items()]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    frames: list[bytes] = []
    replies: list[list[bytes]] = []
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 15)
        assert ready, "the harness did not report its port"
        line = proc.stdout.readline()
        assert line.startswith("PORT "), line
        harness_addr = ("127.0.0.1", int(line.split()[1]))
        bridge.sendto(TICK, harness_addr)
        for k in range(cycles):
            raw, addr = bridge.recvfrom(65536)
            assert addr == harness_addr, "frames must come from the port SimTwo listens on"
            frames.append(raw)
            out = list(policy(k, raw))
            replies.append(out)
            for r in out:
                bridge.sendto(r, addr)
            if k < cycles - 1:
                bridge.sendto(TICK, harness_addr)
        rc = proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        bridge.close()
    lines = rec.read_text().splitlines()
    assert rc == 0, "harness failed:\n" + "\n".join(lines[-20:]) + proc.stderr.read()
    assert lines[-1] == "DONE"
    assert not [x for x in lines if x.startswith(("EXCEPTION", "ERROR"))]
    cyc, cfg0, cfg1 = parse_record(lines)
    return Run(frames, replies, cyc, cfg0, cfg1, lines)


# ---- the rules the script must follow, in Python (docs/protocol.md, docs/simtwo.md) ---------------------

def expected_commands(run: Run, *, same_cycle: bool) -> list[tuple[float, float, int]]:
    """(V, W, S) the script should have in effect after cycle k, from the replies the test sent.

    same_cycle: the replies to frame k are read in cycle k (lockstep with live receive); otherwise in
    cycle k+1 (free running, or lockstep in a SimTwo that only receives between cycles). All datagrams
    read in one cycle are decoded together, first occurrence winning (Command.decode of the concatenation);
    a reply is applied if it decodes and its Seq is -1 or newer than the last applied and not newer than
    the frame just sent; no valid command for more than the timeout stops the wheels, keeping S."""
    timeout = int(run.cfg["CommandTimeoutMs"])
    v = w = 0.0
    s = 0
    last_seq, last_valid = -1, 0
    out = []
    for k in range(len(run.frames)):
        if same_cycle:
            blob = b"".join(run.replies[k])
        else:
            blob = b"".join(run.replies[k - 1]) if k > 0 else b""
        t = PERIOD_MS * (k + 1)
        if blob:
            try:
                cmd = Command.decode(blob)
            except ProtocolError:
                cmd = None
            if cmd is not None and (cmd.seq == -1 or (0 <= cmd.seq <= k and cmd.seq > last_seq)):
                v, w, s = cmd.v, cmd.w, int(cmd.magnet)
                if cmd.seq >= 0:
                    last_seq = cmd.seq
                last_valid = t
        if t - last_valid > timeout:
            v = w = 0.0
        out.append((v, w, s))
    return out


def check_applied(run: Run, expected: list[tuple[float, float, int]]) -> None:
    for k, (v, w, s) in enumerate(expected):
        wl, wr = ROBOT.wheel_speeds(v, w)
        al, ar, vin = run.applied(k)
        assert al == pytest.approx(wl, rel=1e-12, abs=1e-12), f"cycle {k}: left {al} != {wl} (V {v}, W {w})"
        assert ar == pytest.approx(wr, rel=1e-12, abs=1e-12), f"cycle {k}: right {ar} != {wr} (V {v}, W {w})"
        assert vin == s * int(CONST["MAGNET_VIN_ON"]), f"cycle {k}: SetSensorVin {vin}, expected S={s}"


def expected_range(raw: float, z: float) -> float:
    if not (raw >= 0) or not math.isfinite(raw):
        return -1.0
    a, b = ROBOT.lidar.noise_a, ROBOT.lidar.noise_b
    return max(0.0, raw + z * a * math.exp(b * raw))


REAL_RE = re.compile(r"-?\d+(\.\d+)?(E[-+]?\d+)?")


def significant_digits(s: str) -> int:
    mant = s.lstrip("-").split("E")[0].replace(".", "").lstrip("0")
    return len(mant.rstrip("0")) if mant else 0


def close6(decoded: float, true: float) -> bool:
    """decoded is true rounded to 6 significant digits."""
    return abs(decoded - true) <= 5.0001e-6 * abs(true) + 1e-300


def reply(seq: int, v: float, w: float, s: int) -> bytes:
    return Command(v, w, bool(s), seq).encode()


# ---- 1. Pascal sender -> Python decoder, and Python encoder -> Pascal reader ------------------------------

@pytest.fixture(scope="module")
def main_run(harness_exe, tmp_path_factory) -> tuple[Run, float]:
    """30 free-running cycles, a Portuguese locale (decimal comma), deterministic LIDAR noise (z = 0.5),
    one valid reply per frame with speeds in every %.6g style."""
    z = 0.5
    values = [0.3, -0.25, 1.5e-05, -2.5e-07, 0.123456, 0.0, 1.0, -0.999999, 3e-3, 0.05]

    def policy(k, raw):
        f = SensorFrame.decode(raw)
        return [reply(f.seq, values[k % len(values)], values[(3 * k + 1) % len(values)] * 4, (k // 3) % 2)]

    run = run_harness(harness_exe, tmp_path_factory.mktemp("main"), 30, policy, comma=1, noise_z=z)
    return run, z


def test_frames_are_the_protocols_datagrams(main_run):
    run, _ = main_run
    for k, raw in enumerate(run.frames):
        assert raw.endswith(b"\r\n\r\n")
        assert raw.count(b"\r\n") == raw.count(b"\n") == raw.count(b"\r"), "every line ends in CR LF"
        lines = raw.decode("ascii").split("\r\n")[:-1]
        assert lines[0::3] == FRAME_LABELS, f"frame {k}: labels or their order"
        assert all(x == "" for x in lines[2::3])
        # the same labels, in the same order, as the Python encoder writes them
        ref = SensorFrame(0, 0, (0, 0), (0, 0), 0.0, 0.0, 0.0, False, False).encode().decode().split("\r\n")[:-1]
        assert lines[0::3] == ref[0::3]


def test_sensor_values_survive_the_trip(main_run):
    run, z = main_run
    total = [0, 0]
    for k, raw in enumerate(run.frames):
        g = run.cycles[k].get
        f = SensorFrame.decode(raw)
        assert f.seq == k
        assert f.time_ms == PERIOD_MS * (k + 1)
        enc = (int(g["AxisOdo"][0]), int(g["AxisOdo"][1]))
        total = [total[0] + enc[0], total[1] + enc[1]]
        assert f.enc_delta == enc
        assert f.enc_total == tuple(total)
        assert close6(f.x, float(g["RobotX"][0]))
        assert close6(f.y, float(g["RobotY"][0]))
        assert close6(f.theta, float(g["RobotTheta"][0]))
        contact_raw = g["SensorVal"][6]
        assert f.contact == (contact_raw > 0)
        # Magnet: what SetSensorVin applied during the cycle that just ended
        assert int(f.magnet) == run.applied(k - 1)[2]
        raws = g["SensorValues"][8]
        assert len(f.ranges) == len(raws) == 360
        for i, (got, r) in enumerate(zip(f.ranges, raws)):
            exp = expected_range(r, z)
            if exp < 0:
                assert got == -1.0, f"frame {k} ray {i}: raw {r} must be sent as -1"
            else:
                assert close6(got, exp), f"frame {k} ray {i}: {got} != {exp}"
    # the scripted values cover what must be cleaned: NaN, a noisy -1, zero, and a contact
    assert any(math.isnan(r) for r in run.cycles[2].get["SensorValues"][8])
    assert any(SensorFrame.decode(raw).contact for raw in run.frames)


def test_reals_use_a_decimal_point_and_six_digits_in_any_locale(main_run):
    run, _ = main_run  # the harness ran with DecimalSeparator ','
    seen_exponent = False
    for raw in run.frames:
        lines = raw.decode("ascii").split("\r\n")
        vals = dict(zip(lines[0::3], lines[1::3]))
        reals = [vals["X"], vals["Y"], vals["Theta"]] + [r for r in vals["Lidar"].split(";") if r != "-1"]
        for s in reals:
            assert "," not in s
            assert REAL_RE.fullmatch(s), f"{s!r} is not %.6g-style"
            assert significant_digits(s) <= 6, s
            seen_exponent |= "E" in s
        for lab in ("RAF", "Seq", "Tms", "Enc1", "Enc2", "Odo1", "Odo2", "Contact", "Magnet", "LidarN"):
            assert re.fullmatch(r"-?\d+", vals[lab]), (lab, vals[lab])
    assert seen_exponent, "Free Pascal's exponent form (1E-6, 1.23457E6) must occur and decode"


def test_commands_become_wheel_speeds_and_magnet(main_run):
    run, _ = main_run
    check_applied(run, expected_commands(run, same_cycle=False))
    # the script ran every cycle with SimTwo's speed controller on and set the gains at Initialize
    for k in range(len(run.frames)):
        states = [a for n, a in run.cycles[k].sets if n == "MotorControllerState"]
        assert sorted(states) == [["0", "1"], ["1", "1"]]
    pars = [a for n, a in run.cycles[-1].sets if n == "MotorControllerPars"]
    exp = [float(CONST[c]) for c in ("SPEED_KI", "SPEED_KD", "SPEED_KP", "SPEED_KF")]
    assert [[float(x) for x in p[1:]] for p in pars] == [exp, exp]
    # feed-forward is the motors' back-EMF constant
    assert float(CONST["SPEED_KF"]) == ROBOT.motor["Ke"]
    # nothing went wrong: no reply was ignored, no timeout
    assert not [m for m in run.logs() if "ignored" in m or "stopped" in m]


def test_defaults_and_geometry_match_the_project(main_run):
    run, _ = main_run
    assert run.cfg_default["BridgeIP"] == "127.0.0.1"
    assert run.cfg_default["BridgePort"] == "9810"
    assert run.cfg_default["Lockstep"] in ("0", "1")
    assert int(run.cfg_default["CommandTimeoutMs"]) == 500
    assert float(CONST["WHEEL_RADIUS"]) == ROBOT.wheel_radius
    assert float(CONST["TRACK"]) == ROBOT.track
    assert float(CONST["LIDAR_NOISE_A"]) == ROBOT.lidar.noise_a
    assert float(CONST["LIDAR_NOISE_B"]) == ROBOT.lidar.noise_b
    assert round(ROBOT.lidar.period / ROBOT.control_period) == int(CONST["LIDAR_NOISE_EVERY"])
    # the frames went where the settings said (the test's port), from the port SimTwo listens on
    assert run.cfg["BridgePort"] != "9810"
    assert all(line.split()[3] == run.cfg["BridgePort"] for line in run.record if line.startswith("SEND "))


# ---- 2. the reader's rules, case by case ----------------------------------------------------------------

def test_first_occurrence_wins_and_bad_replies_keep_the_last_command(harness_exe, tmp_path):
    crlf = b"\r\n"

    def dgram(pairs, eol=crlf):
        return b"".join(k.encode() + eol + v.encode() + eol + eol for k, v in pairs)

    cases = {
        0: lambda k: [reply(k, 0.2, 0.5, 1)],
        1: lambda k: [reply(k, 0.3, -0.4, 0), reply(k, 0.9, 0.9, 1)],          # two queued: first wins
        2: lambda k: [dgram([("RAF", "1"), ("Seq", str(k)), ("V", "abc"), ("W", "0"), ("S", "0")])],
        3: lambda k: [dgram([("RAF", "2"), ("Seq", str(k)), ("V", "0.1"), ("W", "0"), ("S", "0")])],
        4: lambda k: [reply(k + 10, 0.1, 0.1, 0)],                              # from the future
        5: lambda k: [b"hello\r\nworld\r\n"],                                   # foreign
        6: lambda k: [reply(k, -0.1, 1.5, 1)],
        7: lambda k: [reply(3, 0.5, 0.5, 0)],                                   # stale
        8: lambda k: [reply(-1, 0.05, 0.0, 0)],                                 # unsolicited: applied
        9: lambda k: [dgram([("RAF", "1"), ("Seq", str(k)), ("V", "0.1"), ("W", "0"), ("S", "2")])],
        10: lambda k: [dgram([("RAF", "1"), ("Seq", str(k)), ("V", "0.1"), ("S", "0")])],  # no W
        11: lambda k: [dgram([("RAF", "1"), ("Seq", str(k)), ("V", " +.5e-1 "), ("W", "-2."), ("S", "01")],
                             eol=b"\n")],                                       # LF only, odd but valid
        12: lambda k: [b"RAF\r1\r\rSeq\r" + str(k).encode() + b"\r\rV\r0.01\r\rW\r0\r\rS\r1\r\r"],  # CR only
        13: lambda k: [reply(k, 0.7, 0.0, 0) + b"\xe9"],                       # not ASCII
        14: lambda k: [dgram([("RAF", "1"), ("Seq", str(k)), ("V", "0.11")]), reply(k, 0.9, 0.12, 1)],
        15: lambda k: [reply(k, 0.4, -0.3, 0), b"x" * 5000],                  # long junk after a reply
    }
    n = max(cases) + 3

    def policy(k, raw):
        return cases[k](k) if k in cases else []

    run = run_harness(harness_exe, tmp_path, n, policy)
    exp = expected_commands(run, same_cycle=False)
    check_applied(run, exp)
    # spot checks of the rules themselves, beyond agreeing with the Python decoder
    assert exp[2][:2] == (0.3, -0.4)                 # cycle 1's first reply, not the second
    assert exp[3] == exp[2] == exp[4] == exp[5] == exp[6]   # garbled, version 2, future, foreign: kept
    assert exp[8] == exp[7] == (-0.1, 1.5, 1)          # stale Seq 3 after Seq 6: kept
    assert exp[9][:2] == (0.05, 0.0)                 # Seq -1 applied
    assert exp[12][:2] == (0.05, -2.0)               # LF-only datagram with " +.5e-1 ", "-2.", "01"
    assert exp[13][:2] == (0.01, 0.0)                # CR-only datagram
    assert exp[14] == exp[13]                        # a non-ASCII byte spoils the whole reply
    assert exp[15][:2] == (0.11, 0.12)               # labels from both datagrams: V first, W second
    assert exp[16][:2] == (0.4, -0.3)
    # the reasons of the first three (later ones are counted, and logged every 250th)
    logs = [m for m in run.logs() if "ignored" in m]
    assert len(logs) == 3
    for m, reason in zip(logs, ("V is not a real number", "protocol version 2", "Seq 14 is not newer")):
        assert reason in m


def _random_reply(rng: random.Random, k: int, last: int) -> list[bytes]:
    """A mix of valid, odd-but-valid and broken replies to frame k."""
    def num(x: float) -> str:
        return rng.choice(["%.6g" % x, repr(x), f" {x} ", "%.3e" % x, "%E" % x, ("+%g" % x) if x >= 0 else "%g" % x])

    def bad() -> str:
        return rng.choice(["", "abc", "1.2.3", "nan", "inf", "--1", "1e", ".", "0x10", "1,5", "e5"])

    seq = rng.choice([k, k, k, k, -1, last, max(last - 2, 0), k + 3, k + 50])
    pairs = [["RAF", rng.choice(["1", "1", "1", " 1", "01", "2"])], ["Seq", str(seq)],
             ["V", num(round(rng.uniform(-1, 1), 4))], ["W", num(rng.uniform(-6, 6))],
             ["S", rng.choice(["0", "1", "0", "1", "01", "2", "-1", "1.0"])]]
    r = rng.random()
    if r < 0.12:
        rng.choice(pairs)[1] = bad()
    elif r < 0.2:
        pairs.pop(rng.randrange(len(pairs)))
    elif r < 0.3:
        i = rng.randrange(len(pairs))
        pairs.insert(rng.randrange(len(pairs) + 1), [pairs[i][0], num(rng.uniform(-1, 1))])
    rng.shuffle(pairs) if rng.random() < 0.2 else None
    eol = rng.choice([b"\r\n", b"\r\n", b"\r\n", b"\n", b"\r"])
    out = [b"".join(a.encode() + eol + b.encode() + eol + eol for a, b in pairs)]
    r = rng.random()
    if r < 0.1:
        out.append(reply(k, rng.uniform(-1, 1), rng.uniform(-1, 1), 1))
    elif r < 0.15:
        out.insert(0, b"hello\r\n")
    elif r < 0.2:
        out = []
    elif r < 0.23:
        out[0] += b"\xff"
    return out


def test_reader_agrees_with_the_python_decoder_on_mixed_replies(harness_exe, tmp_path):
    rng = random.Random(20240611)
    state = {"last": -1}

    def policy(k, raw):
        out = _random_reply(rng, k, state["last"])
        try:
            c = Command.decode(b"".join(out))
            if c.seq >= 0:
                state["last"] = max(state["last"], min(c.seq, k))
        except ProtocolError:
            pass
        return out

    run = run_harness(harness_exe, tmp_path, 90, policy)
    exp = expected_commands(run, same_cycle=False)
    check_applied(run, exp)
    changes = sum(1 for a, b in zip(exp, exp[1:]) if a != b)
    ignored = sum(1 for m in run.logs() if "ignored" in m)
    assert changes > 20 and ignored > 0, "the mix must exercise both accepting and rejecting"


# ---- 3. no reply: the wheels stop after the timeout, never a block --------------------------------------

def test_no_reply_stops_the_wheels_after_the_timeout_and_keeps_the_magnet(harness_exe, tmp_path):
    silent = range(5, 25)

    def policy(k, raw):
        return [] if k in silent else [reply(k, 0.25, 0.8, 1)]

    run = run_harness(harness_exe, tmp_path, 30, policy)
    exp = expected_commands(run, same_cycle=False)
    check_applied(run, exp)
    timeout = int(run.cfg["CommandTimeoutMs"])
    stopped = [k for k, (v, w, s) in enumerate(exp) if k > 0 and v == w == 0.0]
    assert stopped, "the wheels must stop"
    # the last reply (to frame 4) was applied in cycle 5; the stop comes once more than the timeout passed
    assert stopped[0] == min(k for k in range(6, 30) if PERIOD_MS * (k + 1) - PERIOD_MS * 6 > timeout)
    assert all(exp[k][2] == 1 for k in stopped), "the magnet is not dropped by the timeout"
    assert stopped[-1] == silent.stop, "the first reply after the silence releases the wheels"
    logs = run.logs()
    assert sum("wheels stopped" in m for m in logs) == 1
    assert sum("wheels released" in m for m in logs) == 1
    assert max(c.duration_ms for k, c in run.cycles.items() if k >= 0) < 500, "free running never waits"


# ---- 4. lockstep ----------------------------------------------------------------------------------------

def test_lockstep_applies_the_reply_in_the_same_cycle_and_waits_a_bounded_time(harness_exe, tmp_path):
    wait = 1500

    def policy(k, raw):
        f = SensorFrame.decode(raw)
        if k in (4, 5):
            return []
        if k == 7:
            return [reply(f.seq, 0.6, 0.0, 1), reply(f.seq, -0.6, 2.0, 0)]
        return [reply(f.seq, 0.01 * k, -0.1 * k, k % 2)]

    run = run_harness(harness_exe, tmp_path, 10, policy, lockstep=1, live=1, wait_ms=wait,
                      frame_timeout=wait / 1000 + 10)
    exp = expected_commands(run, same_cycle=True)
    check_applied(run, exp)
    assert exp[3][:2] == (0.03, pytest.approx(-0.3)) and exp[4] == exp[5] == exp[3]
    assert exp[7][:2] == (0.6, 0.0)
    for k in (4, 5):
        assert wait <= run.cycles[k].duration_ms < wait + 1000, "a missing reply costs the wait, no more"
    assert all(run.cycles[k].duration_ms < wait for k in (0, 1, 2, 3, 6, 7, 8, 9))


def test_lockstep_in_a_simtwo_that_receives_only_between_cycles(harness_exe, tmp_path):
    """If SimTwo's UDP receive only runs in its event loop, no reply can arrive during Control: every
    wait runs out, and the reply to frame k is applied in cycle k+1 (free running plus the wait)."""
    wait = 60

    def policy(k, raw):
        return [reply(SensorFrame.decode(raw).seq, 0.02 * k, 0.3, 1)]

    run = run_harness(harness_exe, tmp_path, 8, policy, lockstep=1, live=0, wait_ms=wait)
    check_applied(run, expected_commands(run, same_cycle=False))
    for k in range(8):
        assert wait <= run.cycles[k].duration_ms < wait + 800
    assert sum("lockstep: no reply" in m for m in run.logs()) == 3, "rate-limited: the first three"


# ---- 5. a scene without the sensors ---------------------------------------------------------------------

def test_missing_robot_axes_and_sensors(harness_exe, tmp_path):
    run = run_harness(harness_exe, tmp_path, 4, lambda k, raw: [reply(k, 0.1, 0.0, 1)],
                      missing="AGV,LeftAxis,ranger2d,solenoid1,MicroSwitch")
    for raw in run.frames:
        f = SensorFrame.decode(raw)
        assert len(f.ranges) == 0 and not f.contact and not f.magnet
        assert b"LidarN\r\n0\r\n\r\nLidar\r\n\r\n\r\n" in raw
    assert not [1 for c in run.cycles.values() for n, _ in c.sets if n == "SensorVin"]
    al, ar, _ = run.applied(3)
    assert (al, ar) == pytest.approx(ROBOT.wheel_speeds(0.1, 0.0))
    init = " ".join(run.cycles[-1].logs)
    for name in ("robot AGV", "axis LeftAxis", "ranger2d", "solenoid1", "MicroSwitch"):
        assert name in init


# ---- 6. only what SimTwo's PascalScript offers ------------------------------------------------------------

PASCAL_KEYWORDS = set("""and array begin boolean break byte case char const continue div do double downto else end
exit extended false for function if integer longword mod not of or procedure result string then to true until
var while""".split())
BUILTINS = {"length", "copy", "pos", "ord", "inttostr", "round"}  # PascalScript's own
# SimTwo's script API with the signatures it publishes (ODERobotsPublished, dynmatrix, the editor's)
SIMTWO_API = {
    "Format": None,
    "WriteLn": "procedure WriteLn(S: string)",
    "WriteUDPData": "procedure WriteUDPData(ToIP: string; ToPort: integer; s: string)",
    "ReadUDPData": "function ReadUDPData: string",
    "ReadUDPPacket": "function ReadUDPPacket: string",
    "GetUDPPacketCount": "function GetUDPPacketCount: integer",
    "ScriptPeriod": "function ScriptPeriod: double",
    "GetTickCount": "function GetTickCount: LongWord",
    "RandG": "function RandG(Mean, StdDev: Extended): Extended",
    "Exp": None,
    "GetRobotIndex": "function GetRobotIndex(ID: string): integer",
    "GetAxisIndex": "function GetAxisIndex(R: integer; ID: string; i: integer): integer",
    "GetSensorIndex": "function GetSensorIndex(R: integer; ID: string): integer",
    "GetAxisOdo": "function GetAxisOdo(R, i: integer): integer",
    "GetRobotX": "function GetRobotX(R: integer): double",
    "GetRobotY": "function GetRobotY(R: integer): double",
    "GetRobotTheta": "function GetRobotTheta(R: integer): double",
    "GetSensorVal": "function GetSensorVal(R, i: integer): double",
    "GetSensorValues": "function GetSensorValues(R, i: integer): Matrix",
    "SetSensorVin": "procedure SetSensorVin(R, i: integer; Vin: byte)",
    "SetAxisSpeedRef": "procedure SetAxisSpeedRef(R, i: integer; aSpeed: double)",
    "SetMotorControllerState": "procedure SetMotorControllerState(R, i: integer; newState: boolean)",
    "SetMotorControllerPars": "procedure SetMotorControllerPars(R, i: integer; nKi, nKd, nKp, nKf: double)",
    "MNumRows": "function MNumRows(const Mat: Matrix): Longword",
    "Mgetv": "function Mgetv(const Mat: Matrix; r, c: Longword): double",
    "Matrix": None,
}


def pascal_tokens(text: str) -> list[tuple[str, int, int]]:
    """(token, line, column) without comments and string literals; strings become the token "'"."""
    toks, i, line, col0 = [], 0, 1, 0
    while i < len(text):
        c = text[i]
        if c == "\n":
            line, col0 = line + 1, i + 1
            i += 1
        elif text.startswith("//", i):
            i = text.index("\n", i) if "\n" in text[i:] else len(text)
        elif c == "{":
            j = text.index("}", i)
            line += text.count("\n", i, j)
            i = j + 1
        elif text.startswith("(*", i):
            j = text.index("*)", i)
            line += text.count("\n", i, j)
            i = j + 2
        elif c == "'":
            j = i + 1
            while True:
                j = text.index("'", j)
                if text.startswith("''", j):
                    j += 2
                    continue
                break
            toks.append(("'", line, i - col0))
            i = j + 1
        elif c.isdigit():
            j = i
            while j < len(text) and (text[j].isalnum() or text[j] == "." and text[j + 1 : j + 2].isdigit()):
                j += 1
            toks.append((text[i:j], line, i - col0))
            i = j
        elif c.isalpha() or c == "_":
            j = i
            while j < len(text) and (text[j].isalnum() or text[j] == "_"):
                j += 1
            toks.append((text[i:j], line, i - col0))
            i = j
        elif c.isspace():
            i += 1
        else:
            toks.append((c, line, i - col0))
            i += 1
    return toks


def test_script_uses_only_simtwo_pascalscript():
    toks = pascal_tokens(CONTROL.read_text())
    words = [t for t, _, _ in toks]
    lower = [w.lower() for w in words]
    for banned in ("class", "object", "generic", "specialize", "uses", "program", "unit", "interface",
                   "implementation", "with", "goto", "asm", "inline", "forward", "initialization", "@", "^"):
        assert banned not in lower, f"{banned!r} is not for a SimTwo script"
    # routines only at the top level (PascalScript has no nested routines) and the two entry points
    for t, _, col in toks:
        if t.lower() in ("procedure", "function"):
            assert col == 0, "a routine declared inside another"
    assert "Initialize" in words and "Control" in words
    # every identifier is declared by the script, a keyword, a PascalScript builtin or SimTwo's API
    declared = set()
    mode, depth = None, 0
    for i, (t, _, _) in enumerate(toks):
        lt = t.lower()
        nxt = toks[i + 1][0] if i + 1 < len(toks) else ""
        if lt in ("const", "var") and depth == 0:
            mode = lt
            continue
        if lt in ("procedure", "function"):
            declared.add(nxt.lower())
            mode = "header"
            continue
        if lt == "begin":
            mode = None
        if t == "(":
            depth += 1
        elif t == ")":
            depth -= 1
        if mode == "const" and nxt == "=" and t[0].isalpha():
            declared.add(lt)
        elif mode == "var" and nxt in (",", ":") and t[0].isalpha():
            declared.add(lt)
        elif mode == "header" and depth > 0 and nxt in (",", ":") and t[0].isalpha() and lt not in ("var", "const"):
            declared.add(lt)
    allowed = PASCAL_KEYWORDS | BUILTINS | {n.lower() for n in SIMTWO_API} | declared
    unknown = sorted({w for w in words if (w[0].isalpha() or w[0] == "_") and w.lower() not in allowed})
    assert not unknown, f"not in SimTwo's PascalScript: {unknown}"
    used_api = {n for n in SIMTWO_API if n.lower() in set(lower)}
    assert used_api >= {"WriteUDPData", "ReadUDPData", "GetAxisOdo", "GetSensorValues", "SetAxisSpeedRef",
                        "SetMotorControllerState", "SetSensorVin", "GetSensorIndex"}


def test_stand_in_declares_simtwos_published_signatures():
    text = API.read_text()
    iface = text[text.index("interface") : text.index("implementation")]
    norm = lambda s: re.sub(r"\s+", " ", s.replace(" :", ":").replace("( ", "(")).strip().lower()
    decls = {norm(m.group(0)) for m in
             re.finditer(r"(?:function|procedure)\s+\w+\s*(?:\([^)]*\))?\s*(?::\s*\w+)?", iface)}
    for name, sig in SIMTWO_API.items():
        if sig is not None:
            assert norm(sig) in decls, f"stand-in signature of {name} differs from SimTwo's {sig!r}"
    assert re.search(r"Matrix = record\s+data: array of double;\s+rows: LongWord;\s+cols: LongWord;\s+end;",
                     iface)


# ---- 7. the scene additions ------------------------------------------------------------------------------

def test_lidar_fragment_matches_the_robot_spec():
    root = ET.parse(SIMTWO / "AGV_lidar.xml").getroot()
    assert root.tag == "ranger2d"
    assert root.find("ID").get("value") == CONST["LIDAR_ID"].strip("'")
    beams = root.findall("beam")
    assert float(beams[0].get("length")) == ROBOT.lidar.range_max
    assert float(beams[1].get("angle")) == ROBOT.lidar.fov_deg
    assert int(beams[1].get("rays")) == ROBOT.lidar.rays
    assert float(root.find("period").get("value")) == ROBOT.lidar.period
    assert root.find("noise") is None, "the noise is added by control.pas"
    # AGV.xml's constants: sensor positions are relative to the BasePlate's centre
    agv = {"RobotHeight": 0.018, "RobotThickness": 0.003}
    base_z = agv["RobotHeight"] - agv["RobotThickness"] / 2
    pos = root.find("pos")
    xyz = [eval(pos.get(a), {"__builtins__": {}}, agv) for a in ("x", "y", "z")]
    assert xyz[0] == ROBOT.lidar.xyz[0] and xyz[1] == ROBOT.lidar.xyz[1]
    assert xyz[2] + base_z == pytest.approx(ROBOT.lidar.xyz[2])


def test_settings_files():
    p = configparser.ConfigParser()
    p.read(SIMTWO / "settings" / "config_Params.ini")
    c = p["Config"]
    assert c["CBUDPConnect_Checked"] == "1"
    assert c["EditUDPPort_Text"] == "9808"
    assert c["RGControlBlock_ItemIndex"] == "1"
    assert int(c["EditScriptPeriod_Text"]) == round(ROBOT.control_period * 1000)
    p = configparser.ConfigParser()
    p.read(SIMTWO / "settings" / "config_Cameras.ini")
    assert p["Cameras"]["CBSendImage_Checked"] == "1"
    assert p["Cameras"]["RGImageTransport_ItemIndex"] == "1"
