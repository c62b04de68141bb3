"""simtwo/control.pas proven in SimTwo's own script engine, RemObjects PascalScript, on Linux.

The harness (simtwo/test/pscript/pscript_harness.pas) builds PascalScript's compiler and run-time from
Debian's lazarus-src-2.2 with Free Pascal and sets it up as SimTwo's script editor does (Editor.pas,
Editor.lfm in github.com/P33a/SimTwo): the same plugins and declarations in the same order
(simtwo_plugins.pas, simtwo_decls.inc generated from SimTwo's uPSI_*.pas, the editor's own functions),
icBooleanShortCircuit, SimTwo's header `const MaxDim  = 8; const k = MaxDim-1;` before the script and
`begin Control; end.` after it. So control.pas compiles here exactly when it compiles in SimTwo, and the
negative controls below fail as they would in SimTwo.

It then runs the compiled byte code against a stand-in of the script API (simtwo/test/simtwo_api.pas):
scripted sensor values, every actuator call recorded, real UDP on loopback, ReadUDPData returning
everything received since the previous call, concatenated, and datagrams received only between script
runs (SimTwo receives on the thread that runs the script). The test drives the cycles (a HARNESS-TICK
datagram each), decodes every datagram the script sent with the Python codec
(robotatfactory.simtwo.SensorFrame) and answers with Python-encoded Commands, then checks what the script
applied against the protocol's rules (docs/protocol.md, docs/simtwo.md).

The harness binary is built once into build/pscript-<hash of its sources, fpc's version and PascalScript's
path>/ (about 2.4 s with fpc 3.2.2) and reused until those change.
"""
from __future__ import annotations

import configparser
import hashlib
import json
import math
import os
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
from robotatfactory.simtwo.ports import BRIDGE_UDP_PORT, LOCALHOST, SIMTWO_UDP_PORT

REPO = Path(__file__).resolve().parents[1]
SIMTWO = REPO / "simtwo"
CONTROL = SIMTWO / "control.pas"
API = SIMTWO / "test" / "simtwo_api.pas"
PSDIR = SIMTWO / "test" / "pscript"
HARNESS = PSDIR / "pscript_harness.pas"
# Debian's lazarus-src-2.2 (2.2.6 on Debian 12); any Lazarus version's copy will do
PASCALSCRIPT = max(Path("/usr/lib/lazarus").glob("*/components/PascalScript/Source"),
                   default=Path("/usr/lib/lazarus/2.2.6/components/PascalScript/Source"))
ROBOT_JSON = REPO / "src" / "robotatfactory" / "data" / "robot_simtwo.json"
FRAME_LABELS = ["RAF", "Seq", "Tms", "Enc1", "Enc2", "Odo1", "Odo2", "X", "Y", "Theta", "Contact", "Magnet",
                "LidarN", "Lidar", "PartsN", "Parts"]
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

def harness_sources() -> list[Path]:
    return sorted([API, *PSDIR.glob("*.pas"), *PSDIR.glob("*.inc"), *PSDIR.glob("lcl_shim/*.pas")])


def build_harness() -> Path:
    """The harness binary, built with fpc into build/pscript-<hash>/ unless already there."""
    fpc = shutil.which("fpc")
    if fpc is None:
        pytest.fail("fpc not found: the Free Pascal compiler (Debian package fp-compiler, installed by "
                    "scripts/bootstrap.sh) is required to prove simtwo/control.pas")
    if not (PASCALSCRIPT / "uPSCompiler.pas").exists():
        pytest.fail(f"PascalScript's sources are not in {PASCALSCRIPT}: install Debian's lazarus-src-2.2 "
                    "(scripts/bootstrap.sh does)")
    version = subprocess.run([fpc, "-iV"], capture_output=True, text=True).stdout.strip()
    h = hashlib.sha256(version.encode() + str(PASCALSCRIPT).encode())   # the path names Lazarus' version
    for p in harness_sources():
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    out = REPO / "build" / f"pscript-{h.hexdigest()[:16]}"
    exe = out / "pscript_harness"
    if exe.exists():
        return exe
    tmp = REPO / "build" / f"pscript-tmp-{os.getpid()}-{time.monotonic_ns()}"
    tmp.mkdir(parents=True)
    cmd = [fpc, "-Mdelphi", "-O1", f"-Fu{PSDIR / 'lcl_shim'}", f"-Fu{PASCALSCRIPT}", f"-Fi{PASCALSCRIPT}",
           f"-Fu{API.parent}", f"-Fu{PSDIR}", f"-Fi{PSDIR}", f"-FU{tmp}", f"-FE{tmp}", str(HARNESS)]
    res = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, f"fpc failed:\n{res.stdout[-4000:]}\n{res.stderr}"
    try:
        tmp.rename(out)        # atomic: a parallel build of the same sources just loses the race
    except OSError:
        shutil.rmtree(tmp, ignore_errors=True)
    assert exe.exists()
    for old in (REPO / "build").glob("pscript-*"):   # builds of earlier sources
        if old != out and not old.name.startswith("pscript-tmp-"):
            shutil.rmtree(old, ignore_errors=True)
    return exe


@pytest.fixture(scope="module")
def harness_exe() -> Path:
    return build_harness()


@dataclass
class Compiled:
    ok: bool
    output: str

    @property
    def errors(self) -> list[str]:
        return [x for x in self.output.splitlines() if x.startswith("[Error]")]


def compile_script(exe: Path, script: Path) -> Compiled:
    res = subprocess.run([str(exe), "compile", str(script)], capture_output=True, text=True, timeout=60)
    assert res.returncode in (0, 1), f"the harness crashed ({res.returncode}):\n{res.stdout}{res.stderr}"
    ok = res.returncode == 0
    assert ok == ("Compile OK" in res.stdout), res.stdout
    return Compiled(ok, res.stdout)


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
            elif name in ("AxisOdo", "SensorVal", "PartX", "PartY", "PartTheta"):
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
                script: Path = CONTROL, **opts) -> Run:
    """Runs the harness for `cycles` cycles; policy(k, raw_frame) -> list of reply datagrams."""
    rec = tmp_path / f"record_{time.monotonic_ns()}.txt"
    bridge = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    bridge.bind(("127.0.0.1", 0))
    bridge.settimeout(frame_timeout)
    args = [str(exe), "run", str(script), f"record={rec}", f"cycles={cycles}", f"bridge_port={bridge.getsockname()[1]}",
            "bridge_ip=127.0.0.1"] + [f"{k}={v}" for k, v in opts.items()]
    # unbuffered, so that select() sees every line the harness prints (compile messages, then PORT)
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0)
    frames: list[bytes] = []
    replies: list[list[bytes]] = []
    try:
        line, printed = "", []
        while not line.startswith("PORT "):    # after the compile messages
            ready, _, _ = select.select([proc.stdout], [], [], 15)
            assert ready, "the harness did not report its port"
            line = proc.stdout.readline().decode()
            printed.append(line)
            assert line, "the harness ended before it reported its port:\n" + "".join(printed)
        harness_addr = ("127.0.0.1", int(line.split()[1]))
        bridge.sendto(TICK, harness_addr)
        for k in range(cycles):
            raw, addr = bridge.recvfrom(65536)
            assert addr == harness_addr, f"frames must come from the port SimTwo listens on ({SIMTWO_UDP_PORT})"
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
    assert rc == 0, "harness failed:\n" + "\n".join(lines[-20:]) + proc.stderr.read().decode()
    assert lines[-1] == "DONE"
    assert not [x for x in lines if x.startswith(("EXCEPTION", "ERROR"))]
    cyc, cfg0, cfg1 = parse_record(lines)
    return Run(frames, replies, cyc, cfg0, cfg1, lines)


# ---- the rules the script must follow, in Python (docs/protocol.md, docs/simtwo.md) ---------------------

def expected_commands(run: Run) -> list[tuple[float, float, int]]:
    """(V, W, S) the script should have in effect after cycle k, from the replies the test sent.

    The replies to frame k are read in cycle k+1 (SimTwo receives only between script runs). All datagrams
    read in one cycle are decoded together, first occurrence winning (Command.decode of the concatenation);
    a reply is applied if it decodes and its Seq is -1 or newer than the last applied and not newer than
    the frame just sent; no valid command for more than the timeout stops the wheels, keeping S."""
    timeout = int(run.cfg["CommandTimeoutMs"])
    v = w = 0.0
    s = 0
    last_seq, last_valid = -1, 0
    out = []
    for k in range(len(run.frames)):
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
    """30 cycles, deterministic LIDAR noise (z = 0.5), one valid reply per frame with speeds in every
    %.6g style."""
    z = 0.5
    values = [0.3, -0.25, 1.5e-05, -2.5e-07, 0.123456, 0.0, 1.0, -0.999999, 3e-3, 0.05]

    def policy(k, raw):
        f = SensorFrame.decode(raw)
        return [reply(f.seq, values[k % len(values)], values[(3 * k + 1) % len(values)] * 4, (k // 3) % 2)]

    run = run_harness(harness_exe, tmp_path_factory.mktemp("main"), 30, policy, noise_z=z)
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
        ref = SensorFrame(0, 0, (0, 0), (0, 0), 0.0, 0.0, 0.0, False, False,
                          parts=((0.0, 0.0, 0.0),) * 4).encode().decode().split("\r\n")[:-1]
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
        # the parts: Part1..Part4 of the scene, in order, as SimTwo returned them
        assert len(f.parts) == 4
        for r, (px, py, pth) in enumerate(f.parts, start=1):
            assert close6(px, g["PartX"][r]) and close6(py, g["PartY"][r]) and close6(pth, g["PartTheta"][r])
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


def test_reals_use_a_decimal_point_and_six_digits(main_run):
    run, _ = main_run  # DecimalSeparator '.', as SimTwo forces it at start-up (Viewer.pas 4393)
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
    assert seen_exponent, "the host's Format exponent form (1E-6, 1.23457E6) must occur and decode"


def test_commands_become_wheel_speeds_and_magnet(main_run):
    run, _ = main_run
    check_applied(run, expected_commands(run))
    # SimTwo's speed controller: gains set and controller enabled once, at Initialize (each call of
    # SetMotorControllerState or SetMotorControllerPars resets its integral), never again
    init = [n for n, _ in run.cycles[-1].sets]
    assert init.index("MotorControllerPars") < init.index("MotorControllerState") < init.index("AxisSpeedRef")
    states = [a for n, a in run.cycles[-1].sets if n == "MotorControllerState"]
    assert sorted(states) == [["0", "1"], ["1", "1"]]
    pars = [a for n, a in run.cycles[-1].sets if n == "MotorControllerPars"]
    exp = [float(CONST[c]) for c in ("SPEED_KI", "SPEED_KD", "SPEED_KP", "SPEED_KF")]
    assert sorted(p[0] for p in pars) == ["0", "1"]
    assert [[float(x) for x in p[1:]] for p in pars] == [exp, exp]
    for k in range(len(run.frames)):
        assert not [n for n, _ in run.cycles[k].sets if n.startswith("MotorController")], f"cycle {k}"
    # nothing went wrong: no reply was ignored, no timeout
    assert not [m for m in run.logs() if "ignored" in m or "stopped" in m]


def test_defaults_and_geometry_match_the_project(main_run):
    run, _ = main_run
    assert run.cfg_default["BridgeIP"] == LOCALHOST
    assert run.cfg_default["BridgePort"] == str(BRIDGE_UDP_PORT)
    assert "LOCKSTEP" not in CONST and "GetTickCount" not in CONTROL.read_text(), "no waiting in Control"
    from robotatfactory.sim.runner import RunnerConfig

    # control.pas's command timeout is raf sim's (the stand-in stops the wheels by the same rule)
    assert int(run.cfg_default["CommandTimeoutMs"]) == round(RunnerConfig.command_timeout * 1000) == 400
    assert float(CONST["WHEEL_RADIUS"]) == ROBOT.wheel_radius
    assert float(CONST["TRACK"]) == ROBOT.track
    assert float(CONST["LIDAR_NOISE_A"]) == ROBOT.lidar.noise_a
    assert float(CONST["LIDAR_NOISE_B"]) == ROBOT.lidar.noise_b
    assert round(ROBOT.lidar.period / ROBOT.control_period) == int(CONST["LIDAR_NOISE_EVERY"])
    # the frames went where the settings said (the test's port), from the port SimTwo listens on
    assert run.cfg["BridgePort"] != str(BRIDGE_UDP_PORT)
    assert all(line.split()[3] == run.cfg["BridgePort"] for line in run.record if line.startswith("SEND "))


def _draws(run: Run) -> dict[int, int]:
    """Noise draws (RandG calls) per cycle."""
    out: dict[int, int] = {}
    for line in run.record:
        if line.startswith("DRAW "):
            k = int(line.split()[1])
            out[k] = out.get(k, 0) + 1
    return out


@pytest.mark.parametrize("still", [0, 1])
def test_lidar_noise_is_drawn_once_per_simtwo_sweep(harness_exe, tmp_path, still):
    """SimTwo delivers a whole sweep every 5 cycles and repeats it in between (zeros before the first):
    the script draws new noise for all rays when a new sweep appears and never between SimTwo's sweeps;
    a sweep that repeats exactly (a robot standing still) gets new noise on the same 5-cycle schedule."""
    phase, n = 3, 19
    run = run_harness(harness_exe, tmp_path, n, lambda k, raw: [], noise_z=0.5, sweep=5, sweep_phase=phase,
                      still=still)
    draws = _draws(run)
    for k, count in draws.items():       # all rays with a return at once (none for a -1)
        assert count == sum(1 for r in run.cycles[k].get["SensorValues"][8] if r >= 0), f"cycle {k}"
    # cycle 0: SimTwo's zeros (new); then the sweeps at phase, phase + 5, ...
    assert sorted(draws) == [0] + list(range(phase, n, 5))
    ranges = [SensorFrame.decode(raw).ranges for raw in run.frames]
    for k in range(1, n):
        # the stand-in's noise is deterministic (z = 0.5): frames change exactly when the sweep does
        new_sweep = k == phase or (not still and k in draws)
        assert (ranges[k] == ranges[k - 1]).all() != new_sweep, f"cycle {k}"
    assert (ranges[0] < 0.02).all(), "before the first sweep: SimTwo's zeros plus noise"


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
    exp = expected_commands(run)
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
    exp = expected_commands(run)
    check_applied(run, exp)
    changes = sum(1 for a, b in zip(exp, exp[1:]) if a != b)
    ignored = sum(1 for m in run.logs() if "ignored" in m)
    assert changes > 20 and ignored > 0, "the mix must exercise both accepting and rejecting"


def test_the_stand_in_applies_the_replies_control_pas_applies(harness_exe, tmp_path, field, robot):
    """The same replies, Seq by Seq, into control.pas (the harness) and into raf sim's reader (SimTwo's reply
    timing: the replies to frame k are read together before frame k + 1 is sent): duplicates, replies held
    back behind newer ones, replies to frames not sent yet, unsolicited ones and two queued together leave the
    same command in force after every cycle."""
    import socket as _socket

    from test_sim_runner import make_runner

    rng = random.Random(20261129)
    state = {"last": -1}

    def policy(k, raw):
        if k % 4 == 0:  # a fresh reply now and then: no cycle reaches the command timeout
            seqs = [k]
        else:
            seqs = [rng.choice([k, k, -1, state["last"], max(state["last"] - 2, 0), k + 3, k - 1])
                    for _ in range(rng.choice([1, 1, 2]))]
        if seqs[0] == -1 or 0 <= seqs[0] <= k and seqs[0] > state["last"]:
            state["last"] = max(state["last"], seqs[0])
        return [reply(s, round(rng.uniform(-0.5, 0.5), 3), round(rng.uniform(-2, 2), 3), rng.choice([0, 1]))
                for s in seqs]

    run = run_harness(harness_exe, tmp_path, 60, policy)
    bridge = _socket.socket(_socket.AF_INET, _socket.SOCK_DGRAM)
    bridge.bind(("127.0.0.1", 0))
    runner = make_runner(field, robot, bridge)
    runner.open()
    got = []
    try:
        for k in range(len(run.frames)):
            runner._frame_seq = k  # (cycle k reads the replies to frame k - 1, then sends frame k)
            for dgram in run.replies[k - 1] if k > 0 else []:
                bridge.sendto(dgram, runner.address)
            time.sleep(0.02)
            runner._drain(first_wins=True)
            cmd = runner.command
            got.append((cmd.v, cmd.w, int(cmd.magnet)))
    finally:
        runner.close()
        bridge.close()
    check_applied(run, got)
    assert runner.counters.stale >= 5 and runner.counters.superseded >= 5, "the mix must reject and supersede"


# ---- 3. no reply: the wheels stop after the timeout, never a block --------------------------------------

def test_no_reply_stops_the_wheels_after_the_timeout_and_keeps_the_magnet(harness_exe, tmp_path):
    silent = range(5, 25)

    def policy(k, raw):
        return [] if k in silent else [reply(k, 0.25, 0.8, 1)]

    run = run_harness(harness_exe, tmp_path, 30, policy)
    exp = expected_commands(run)
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
    assert max(c.duration_ms for k, c in run.cycles.items() if k >= 0) < 500, "Control never waits"


def test_teleport_labels_become_setrobotpos_once_each(harness_exe, tmp_path):
    """The Command's teleport labels (robotatfactory.simtwo.teleport, as the bridge's sim/* services send
    them, each repeated): SetRobotPos once per TpId, on the script's robot or a named one (a part); a bad
    teleport is logged and skipped, a malformed Command carries none; the commands still apply."""
    from robotatfactory.simtwo.teleport import Teleport

    robot_tp = Teleport(1, 0.3, -0.2, 1.1).labels()
    part_tp = Teleport(2, -0.3475, 0.075, -1.5, 0.0021, "Part3").labels()
    extra = {2: robot_tp, 3: robot_tp, 4: robot_tp, 5: part_tp, 6: part_tp,
             7: Teleport(3, 0.0, 0.0, 0.0, 0.0, "Nope").labels(),
             8: b"TpId\r\n4\r\n\r\nTpX\r\nfar\r\n\r\nTpY\r\n0\r\n\r\nTpTh\r\n0\r\n\r\n"}

    def policy(k, raw):
        if k == 9:  # not a valid Command (no V): its teleport is not applied either
            return [b"RAF\r\n1\r\n\r\nSeq\r\n9\r\n\r\n" + Teleport(5, 0.1, 0.1, 0.0).labels()]
        return [reply(k, 0.1, 0.2, 0) + extra.get(k, b"")]

    run = run_harness(harness_exe, tmp_path, 12, policy)
    sets = [(k, args) for k, c in sorted(run.cycles.items()) for n, args in c.sets if n == "RobotPos"]
    # the reply to frame k is read in cycle k + 1
    assert [(k, int(a[0])) for k, a in sets] == [(3, 0), (6, 3)]
    assert [float(v) for v in sets[0][1][1:]] == pytest.approx([0.3, -0.2, 0.0, 1.1])
    assert [float(v) for v in sets[1][1][1:]] == pytest.approx([-0.3475, 0.075, 0.0021, -1.5])
    logs = run.logs()
    assert sum("teleport 1:" in m for m in logs) == 1 and sum("teleport 2:" in m for m in logs) == 1
    assert any("teleport 3 ignored: no robot Nope" in m for m in logs)
    assert any("teleport 4 ignored: TpX is not a real number" in m for m in logs)
    assert not any("teleport 5" in m for m in logs)
    assert run.applied(11)[:2] == pytest.approx(ROBOT.wheel_speeds(0.1, 0.2))


# ---- 4. a scene without the sensors ---------------------------------------------------------------------

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


def test_parts_end_at_the_first_missing_one(harness_exe, tmp_path):
    run = run_harness(harness_exe, tmp_path, 2, lambda k, raw: [reply(k, 0.0, 0.0, 0)], missing="Part3")
    for raw in run.frames:
        f = SensorFrame.decode(raw)
        assert len(f.parts) == 2  # Part1, Part2; Part4 is not reached
    (tmp_path / "none").mkdir()
    run = run_harness(harness_exe, tmp_path / "none", 2, lambda k, raw: [reply(k, 0.0, 0.0, 0)], missing="Part1")
    for raw in run.frames:
        assert b"PartsN" not in raw and SensorFrame.decode(raw).parts == ()


# ---- 5. the script compiles in SimTwo's engine, and the engine is SimTwo's -------------------------------

SCRIPT = """// Global Variables Here
{decls}
procedure Control;
{locals}begin
{body}
end;

procedure Initialize;
begin
end;
"""


def script_file(tmp_path: Path, name: str, *, decls: str = "", locals_: str = "", body: str = "") -> Path:
    p = tmp_path / name
    p.write_text(SCRIPT.format(decls=decls, locals=locals_, body=body))
    return p


def test_control_pas_compiles_cleanly_in_simtwos_engine(harness_exe):
    c = compile_script(harness_exe, CONTROL)
    assert c.ok, c.output
    assert c.output.splitlines()[0] == "Compile Messages:0", "no errors, warnings or hints:\n" + c.output


def test_a_local_named_k_fails_as_in_simtwo(harness_exe, tmp_path):
    # SimTwo's header declares k; PascalScript refuses a local that repeats it (Free Pascal would not)
    bad = compile_script(harness_exe, script_file(tmp_path, "k.pas", locals_="var k: integer;\n", body="  k := 1;"))
    assert not bad.ok
    assert len(bad.errors) == 1 and "Duplicate identifier 'k'" in bad.errors[0], bad.output
    assert "(k.pas line 4, column 5)" in bad.output, "the line in the script itself, without the header"
    good = compile_script(harness_exe, script_file(tmp_path, "j.pas", locals_="var j: integer;\n", body="  j := k;"))
    assert good.ok, good.output
    # the shipped script with its former local k back in ParseRealStr
    text = CONTROL.read_text()
    old = text.replace("var i, n, nd, e10, ev, ae, j: integer;", "var i, n, nd, e10, ev, ae, k: integer;")
    old = old.replace("for j := 1 to ae do", "for k := 1 to ae do")
    assert old != text
    (tmp_path / "old.pas").write_text(old)
    bad = compile_script(harness_exe, tmp_path / "old.pas")
    assert not bad.ok and "Duplicate identifier 'k'" in bad.errors[0], bad.output
    # MaxDim too
    bad = compile_script(harness_exe, script_file(tmp_path, "m.pas", decls="var MaxDim: double;\n"))
    assert not bad.ok and "Duplicate identifier 'MaxDim'" in bad.errors[0], bad.output


def test_only_what_simtwo_registers_exists(harness_exe, tmp_path):
    # not registered by SimTwo (nor by PascalScript): Free Pascal's RTL has them, a script does not
    for call in ("SetWheelSpeed(0, 1.0);", "Sleep(10);", "x := FloatToStrF(1.5, ffFixed, 8, 2);",
                 "x := GetRobotZ(0);"):
        c = compile_script(harness_exe, script_file(tmp_path, "u.pas", locals_="var x: string;\n", body="  " + call))
        assert not c.ok and "Unknown identifier" in c.errors[0], (call, c.output)
    # registered by SimTwo, through each source of declarations: ODERobotsPublished, dynmatrix,
    # PathFinder, user_charts, the editor, PascalScript's Classes/Controls/Forms imports, the registered
    # variables, the header
    body = """  x := GetRobotX(0) + Mgetv(Mzeros(2, 2), 1, 1) + GetAStarPathCount + Time + MaxDim + k;
  ChartSeriesClear(0, 0);
  WriteUDPData('127.0.0.1', 9810, Format('%.3f', [ATan2(1, 2)]));
  L := TStringList.Create; L.Free;
  HUDStrings.Add(IntToStr(RandSeed));
  SetAxisSpeedRef(0, 0, x);"""
    c = compile_script(harness_exe, script_file(tmp_path, "r.pas", locals_="var x: double; L: TStringList;\n",
                                                body=body))
    assert c.ok, c.output


def test_wrong_arguments_fail_to_compile(harness_exe, tmp_path):
    cases = {
        "SetAxisSpeedRef(0, 1);": "Invalid number of parameters",           # one missing
        "SetMotorControllerPars(0, 0, 1, 2, 3);": "Invalid number of parameters",
        "x := GetSensorIndex(0, 5);": "Type mismatch",                       # ID is a string
        "WriteUDPData('127.0.0.1', '9810', 'x');": "Type mismatch",          # port is an integer
        "x := GetAxisOdo(0);": "Invalid number of parameters",
    }
    for call, msg in cases.items():
        c = compile_script(harness_exe, script_file(tmp_path, "w.pas", locals_="var x: integer;\n", body="  " + call))
        assert not c.ok and msg in c.errors[0], (call, c.output)
    c = compile_script(harness_exe, script_file(tmp_path, "ok.pas", locals_="var x: integer;\n",
                                                body="  SetAxisSpeedRef(0, 1, 2.5); x := GetAxisOdo(0, 1);"))
    assert c.ok, c.output


def test_boolean_evaluation_short_circuits_as_in_simtwo(harness_exe, tmp_path):
    """SimTwo compiles with icBooleanShortCircuit: the right side of `and`/`or` is not evaluated when the
    left decides. Here it would read row 999 of a sensor's 1 x 1 matrix, which the stand-in refuses."""
    decls = "var n: integer;\n    CfgBridgeIP: string;\n    CfgBridgePort: integer;   // set by the harness, as for control.pas\n"
    body = """  n := n + 1;
  if (n < 0) and (Mgetv(GetSensorValues(0, 5), 999, 0) > 0) then WriteLn('never');
  if (n > 0) or (Mgetv(GetSensorValues(0, 5), 999, 0) > 0) then
    WriteUDPData(CfgBridgeIP, CfgBridgePort, 'RAF' + #13#10 + '1' + #13#10);"""
    script = script_file(tmp_path, "sc.pas", decls=decls, body=body)
    run = run_harness(harness_exe, tmp_path, 3, lambda k, raw: [], script=script)
    assert run.frames == [b"RAF\r\n1\r\n"] * 3
    # and the stand-in does refuse: when the right side runs, the script stops with its error
    script.write_text(script.read_text().replace("(n < 0) and", "(n > 0) and"))
    rc, record = run_to_error(harness_exe, tmp_path, script)
    assert rc == 3 and "outside a 1 x 1 matrix" in record[-2] and record[-1] == "DONE", record[-3:]


def run_to_error(exe: Path, tmp_path: Path, script: Path) -> tuple[int, list[str]]:
    """Runs a script that must fail in its first cycle: (exit code, record lines)."""
    rec = tmp_path / "error_record.txt"
    tick = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    proc = subprocess.Popen([str(exe), "run", str(script), f"record={rec}", "cycles=1", "tick_timeout_ms=5000"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, bufsize=0)
    try:
        line = b""
        while not line.startswith(b"PORT "):
            ready, _, _ = select.select([proc.stdout], [], [], 15)
            assert ready, "the harness did not report its port"
            line = proc.stdout.readline()
            assert line, "the harness ended before it reported its port"
        tick.sendto(TICK, ("127.0.0.1", int(line.split()[1])))
        rc = proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        tick.close()
    return rc, rec.read_text().splitlines()


# ---- 6. the stand-in matches the declarations it is registered under -------------------------------------

def _norm_decl(decl: str) -> tuple[str, tuple, str]:
    """'function F(a, b: integer; const M: Matrix): double' -> ('f', (('', 'integer'), ('', 'integer'),
    ('const', 'matrix')), 'double')."""
    m = re.fullmatch(r"\s*(function|procedure)\s+(\w+)\s*(?:\((.*)\))?\s*(?::\s*(\w+))?\s*;?\s*", decl, re.S | re.I)
    assert m, decl
    params = []
    for group in filter(None, (g.strip() for g in (m.group(3) or "").split(";"))):
        names, typ = group.rsplit(":", 1)
        mode = ""
        first = names.split()[0].lower()
        if first in ("const", "constref", "var", "out"):
            # constref: the stand-in's spelling of SimTwo's by-reference const record (simtwo_api.pas)
            mode, names = first.replace("constref", "const"), names.strip()[len(first):]
        params += [(mode, typ.strip().lower())] * len([n for n in names.split(",") if n.strip()])
    return m.group(2).lower(), tuple(params), (m.group(4) or "").lower()


def _registered_decls() -> dict[str, tuple]:
    """Every declaration the harness registers, by name (SimTwo's import units and editor)."""
    text = (PSDIR / "simtwo_decls.inc").read_text() + (PSDIR / "pscript_harness.pas").read_text()
    out = {}
    for d in re.findall(r"AddFunc\(CL, '([^']*)'\)", text) + re.findall(r"Fn(?:Stack)?\(Sender, @?\w+, '([^']*)'\)", text):
        n = _norm_decl(d)
        out.setdefault(n[0], n)
    return out


def test_stand_in_functions_have_simtwos_signatures():
    decls = _registered_decls()
    assert len(decls) > 300, "SimTwo's import units and editor declare some 300 routines"
    iface = API.read_text()
    iface = iface[iface.index("interface") : iface.index("{ ---- the harness side")]
    stand_ins = re.findall(r"((?:function|procedure)\s+\w+\s*(?:\([^)]*\))?\s*(?::\s*\w+)?\s*;)", iface)
    assert len(stand_ins) >= 20
    for s in stand_ins:
        name, params, result = _norm_decl(s)
        assert name in decls, f"{name}: SimTwo registers no such routine"
        # parameter modes and types, and the result: what the native call depends on
        assert (params, result) == decls[name][1:], f"{s!r} differs from SimTwo's {decls[name]}"
    # SimTwo's Matrix (dynmatrix) and the stand-in's record have the same fields in the same order
    assert "AddType(CL, 'Matrix', 'record data : array of double; rows : Longword; cols : Longword; end');" in \
        (PSDIR / "simtwo_decls.inc").read_text()
    assert re.search(r"Matrix = record\s+data: array of double;\s+rows: LongWord;\s+cols: LongWord;\s+end;", iface)


def test_speed_gains_are_robot_simtwo_json_simtwo_pid():
    pid = json.loads(ROBOT_JSON.read_text())["simtwo_pid"]
    assert int(CONST["SET_SPEED_GAINS"]) == 1
    for const, key in (("SPEED_KP", "kp"), ("SPEED_KI", "ki"), ("SPEED_KD", "kd"), ("SPEED_KF", "kf")):
        assert float(CONST[const]) == pytest.approx(float(pid[key]), rel=1e-12, abs=0), const


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
    assert c["EditUDPPort_Text"] == str(SIMTWO_UDP_PORT)
    assert c["RGControlBlock_ItemIndex"] == "1"
    assert int(c["EditScriptPeriod_Text"]) == round(ROBOT.control_period * 1000)
    p = configparser.ConfigParser()
    p.read(SIMTWO / "settings" / "config_Cameras.ini")
    assert p["Cameras"]["CBSendImage_Checked"] == "1"
    # SimTwo does not store the transport (ZMQ is its start-up default): a line for it would do nothing
    assert "RGImageTransport_ItemIndex" not in p["Cameras"]
