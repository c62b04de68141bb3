"""``raf bench drive``: one scripted drive, on the stand-in (``raf sim``) or the real SimTwo, the same figures.

Each run starts the simulator in real time, as SimTwo runs (the stand-in: ``raf sim`` as a subprocess with its
SimTwo-like defaults, free running, not lockstep, field ``simtwo2022``, camera on; SimTwo: ``raf simtwo
run``'s SimTwoRun, camera open), and a scripted bridge in this process answers every SensorFrame at once with
the command of the drive's current segment. The drive starts at the scene's start pose (no teleport: SimTwo
has none here) and stays in the west column and the north-west corner, clear of the machines and warehouses
(``clearance_min_m`` says by how much, from the ground truth): settle, straight north, an arc right (V 0.2
m/s, W -0.5 rad/s, a quarter turn), half a turn on the spot at 0.5 rad/s, the arc left back on the same
circle, straight south, half a turn on the spot at 1.5 rad/s and straight on at once (the spin -> straight
transition), stop. Short pauses separate the segments except that last transition.

Figures, flat, with units; ``run`` gives min / median / max over ``--repeats``:

- rates: SensorFrames per second of simulation and of wall time, the simulator's clock against the wall;
- replies applied: the share of cycles in which the simulator applied a new reply. SimTwo: control.pas's
  status line (``frames N, replies applied A``); the stand-in: ``raf sim``'s status line (``sent N ... applied
  A``: cycles that got a new command per frame sent; with its default ``--reply-timing simtwo`` only the first
  script call of a GUI turn reads, as SimTwo's);
- camera: frames per wall second, and how long after the SensorFrame before it each arrives (median, p90: an
  upper bound of its latency);
- LIDAR: sweeps per second (a sweep = a new set of ranges), returns per sweep inside the robot's outline (the
  bridge's self-filter footprint, ``simtwo/selfhits.py``), and the range error against the field's walls and
  ribs (``field`` ``simtwo2022``) cast from the ground-truth pose: at rest, and while moving with each ray's
  own measuring instant (SimTwo's sweep schedule, ``sim/sensors.py``);
- odometry (the encoders' totals through DiffDriveOdometry) against the ground truth, per segment: distance
  ratio for straights, turn error, position error per metre driven, for turns on the spot the truth's turn
  over the encoders'; and over the whole drive.

``--carry`` (:func:`carry_drive`, ``one_run(carry=True)``): pick and carry, the same segments with a part on the
magnet, each segment timed by the simulation's clock (the plain drive: the wall's). The robot starts 75 mm east
of the scene's start pose (:data:`CARRY_START`; the stand-in: ``--start-pose``, SimTwo: a teleport of the
robot), so that the held part's outline stays on the board and clear of the ribs
through both spins. During the longer settle, Part1 is teleported (SimTwo: the Command's teleport labels,
TpTarget ``Part1``, as the bridge's ``sim/place_part`` does; the stand-in: its control channel's
``place_part``, as the bridge does there) :data:`CARRY_GAP_M` short of where a held part sits, plate towards the
robot, and the magnet is switched on (S = 1) in the same reply; it stays on to the end. From the frames'
``Parts`` (part 1, SimTwo's heading: the plate's + pi/2) and the robot's ground truth, per segment and over the
carry (settle's end -> stop's end): the part's offset from where a held part sits (``held_x`` = the magnet's
face + the part's depth / 2 ahead of base_link, as ``competition/live.py``), along and across (mm), its rotation
against the robot (deg), max and final; lost = more than :data:`CARRY_LOST_M` from the held position
(``carry_lost`` 0/1, ``carry_lost_at_s`` after settle's end). The robot's and the part's outlines' clearance of the
field's boxes, the other parts and the board's edge (the part's feet) over the drive.
"""
from __future__ import annotations

import bisect
import math
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

NAME = "drive"
HELP = ("one scripted drive on the stand-in or the real SimTwo (--simulator): rates, replies applied, camera, "
        "LIDAR, odometry per segment against the ground truth (no ROS)")
TARGETS = {"frames_per_s_sim_median": "25 (the 40 ms script period)",
           "clearance_min_m_min": "> 0.03 (the route stays clear of posts and walls)"}
SIMULATORS = ("standin", "simtwo")
FIELD = "simtwo2022"
V = 0.2  # m/s on straights and arcs
ARC_W = 0.5  # rad/s on arcs: radius 0.4 m
SPIN_SLOW, SPIN_FAST = 0.5, 1.5  # rad/s, turns on the spot
STATUS_EVERY = 125  # control.pas's status line every 125 cycles (5 s)
# the carry: start 75 mm east of the scene's start pose (-0.725, -0.4): a held part reaches 0.15 m from the axle,
# and the fast spin (clockwise, through west) would take its feet off the board's west edge (x = -0.84)
CARRY_START = (-0.65, -0.4, math.pi / 2)
CARRY_PART = 1  # SimTwo's Part1 (incoming slot 1), SensorFrame.parts[0]
# the part is placed this far beyond the held position, plate towards the robot: SimTwo's solenoid face is 5 mm
# further ahead than the stand-in's and its plate 0.5 mm thicker (measured: a part held 7 mm beyond held_x, the
# stand-in's 2 mm), so at 6 mm SimTwo's plate overlapped the face by 1.5 mm and ODE threw the part away at
# 0.3 m/s; at 12 mm it is 5 mm (SimTwo) or 10 mm (stand-in) clear of the face, within the ray's 15 mm beyond it
CARRY_GAP_M = 0.012
CARRY_PLACE_S = 1.5  # s after the first frame: the part's teleport and the magnet on (the robot at rest by then)
CARRY_LOST_M = 0.025  # m from the held position: lost


@dataclass(frozen=True)
class Segment:
    name: str
    seconds: float
    v: float  # m/s
    w: float  # rad/s

    @property
    def kind(self) -> str:
        if self.v == 0 and self.w == 0:
            return "rest"
        return "spin" if self.v == 0 else ("straight" if self.w == 0 else "arc")


def default_drive() -> tuple[Segment, ...]:
    """The drive from ``simtwo2022``'s start pose (-0.725, -0.4, heading +y): up the west column, a quarter
    turn right on a 0.4 m circle into the north band, half a turn on the spot there (0.5 rad/s, anticlockwise),
    back along the same circle, down the column, half a turn clockwise at 1.5 rad/s (clockwise so that the
    extra turn of the transition takes the robot away from the floor's west edge) and straight north at once."""
    q, h = math.pi / 2, math.pi
    return (Segment("settle", 2.0, 0, 0), Segment("straight", 1.5, V, 0),
            Segment("arc_right", q / ARC_W, V, -ARC_W), Segment("pause1", 0.5, 0, 0),
            Segment("spin_slow", h / SPIN_SLOW, 0, SPIN_SLOW), Segment("pause2", 0.5, 0, 0),
            Segment("arc_left", q / ARC_W, V, ARC_W), Segment("pause3", 0.5, 0, 0),
            Segment("straight_south", 1.5, V, 0), Segment("pause4", 0.5, 0, 0),
            Segment("spin_fast", h / SPIN_FAST, 0, -SPIN_FAST), Segment("after_spin", 1.5, V, 0),
            Segment("stop", 1.5, 0, 0))


def carry_drive() -> tuple[Segment, ...]:
    """:func:`default_drive` with a longer settle (the part is placed at CARRY_PLACE_S and pulled in), from
    CARRY_START: the same segments, 75 mm further east."""
    plan = default_drive()
    return (Segment("settle", 4.0, 0, 0),) + plan[1:]


# ------------------------------------------------------------------------------------------ the simulators
class _StandIn:
    """``raf sim`` as a subprocess: real time, free running, SimTwo-like defaults, field simtwo2022."""

    status_re = re.compile(r"sent (\d+) cmd \d+ applied (\d+)")

    def __init__(self, camera: bool, seed: int = 0, extra: tuple = (), carry: bool = False):
        from ..proc import free_port

        self.camera, self.seed, self.extra, self.carry = camera, seed, tuple(extra), carry
        self.bridge_port = free_port(socket.SOCK_DGRAM)
        self.camera_port = free_port()
        self.control_port = free_port(socket.SOCK_DGRAM) if carry else None
        self.tmp = Path(tempfile.mkdtemp(prefix="raf-bench-drive-"))
        self.proc: subprocess.Popen | None = None
        self.ready_s = None
        self.placed: dict | None = None  # the control channel's answer to place_part

    def start(self) -> None:
        from ..proc import free_port

        cmd = [sys.executable, "-m", "robotatfactory", "--field", FIELD, "sim", "--realtime",
               "--port", str(free_port(socket.SOCK_DGRAM)), "--bridge", f"127.0.0.1:{self.bridge_port}",
               "--no-server", "--seed", str(self.seed), "--status-every", "1"]
        if self.carry:  # all four parts in their incoming slots, as SimTwo's scene; the control channel places one
            cmd += ["--control-port", str(self.control_port), "--parts", "BBBB",
                    "--start-pose=" + ",".join(f"{a:.6f}" for a in CARRY_START)]
        else:
            cmd += ["--no-control"]
        cmd += list(self.extra)
        cmd += ["--camera-bind", f"tcp://127.0.0.1:{self.camera_port}"] if self.camera else ["--no-camera"]
        self._log = open(self.tmp / "sim.log", "wb")
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True)

    def log_text(self) -> str:
        return (self.tmp / "sim.log").read_text(errors="replace")

    def place_part(self, pid: int, x: float, y: float, facing: float) -> None:
        """The bridge's sim/place_part on the stand-in: the control channel's place_part, in a thread (the
        request waits for the next cycle boundary; the bench's replies must not)."""
        from ..sim.control import ControlClient

        def place():
            try:
                self.placed = ControlClient(("127.0.0.1", self.control_port), timeout=2.0).request(
                    "place_part", part=pid, x=x, y=y, facing=facing)
            except ConnectionError as e:
                self.placed = {"ok": False, "message": str(e)}

        threading.Thread(target=place, daemon=True).start()

    def check(self) -> None:
        if self.proc is not None and self.proc.poll() is not None:
            raise RuntimeError(f"raf sim exited with {self.proc.returncode}:\n{self.log_text()[-3000:]}")

    def status(self) -> list[tuple[int, int]]:
        """(frames sent, cycles that applied a new command) of each status line so far."""
        return [tuple(map(int, m)) for m in self.status_re.findall(self.log_text())]

    def stop(self) -> None:
        import shutil

        from ..proc import stop_process

        if self.proc is not None:
            stop_process(self.proc)
        self._log.close()
        shutil.rmtree(self.tmp, ignore_errors=True)


class _SimTwo:
    """The real SimTwo (the Linux build), control.pas with a status line every STATUS_EVERY cycles."""

    status_re = re.compile(r"frames (\d+), replies applied (\d+), ignored (\d+)")

    def __init__(self, camera: bool):
        from ..simtwo_linux.run import Ports

        self.camera = camera
        self.ports = Ports.free()
        self.bridge_port, self.camera_port = self.ports.bridge, self.ports.camera
        self.tmp = Path(tempfile.mkdtemp(prefix="raf-bench-simtwo-"))
        self.run = None
        self.ready_s = None

    def start(self) -> None:
        from ..simtwo_linux import build
        from ..simtwo_linux.run import SimTwoRun
        from ..simtwo_linux.scene import SIMTWO_DIR

        text = (SIMTWO_DIR / "control.pas").read_text(encoding="latin-1")
        text = re.sub(r"^(\s*STATUS_EVERY\s*=\s*)\d+;", rf"\g<1>{STATUS_EVERY};", text, count=1, flags=re.M)
        (self.tmp / "control.pas").write_text(text, encoding="latin-1")
        self.run = SimTwoRun(build.require(), self.ports, camera=self.camera, script=self.tmp / "control.pas")
        self.run.start()
        self.ready_s = self.run.ready_s

    def log_text(self) -> str:
        return self.run.log_text()

    def check(self) -> None:
        self.run.check()

    def status(self) -> list[tuple[int, int, int]]:
        """(frames, replies applied, ignored) of each status line so far."""
        return [tuple(map(int, m)) for m in self.status_re.findall(self.log_text())]

    def stop(self) -> None:
        import shutil

        if self.run is not None:
            self.run.stop()
        shutil.rmtree(self.tmp, ignore_errors=True)


# ------------------------------------------------------------------------------------------ geometry
def field_boxes(field, scan_z: float) -> list:
    """The field's boxes that the scan plane cuts: (cx, cy, hx, hy, cos yaw, sin yaw)."""
    return [b.plan for b in field.boxes_at_height(scan_z)]


def cast(boxes: list, ox: np.ndarray, oy: np.ndarray, dx: np.ndarray, dy: np.ndarray) -> np.ndarray:
    """Distance along each ray (origin o, unit direction d, world frame) to the nearest box face; inf if none."""
    best = np.full(np.broadcast(ox, dx).shape, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        for cx, cy, hx, hy, c, s in boxes:
            px, py = (ox - cx) * c + (oy - cy) * s, -(ox - cx) * s + (oy - cy) * c  # into the box's frame
            ux, uy = dx * c + dy * s, -dx * s + dy * c
            t1, t2 = (-hx - px) / ux, (hx - px) / ux
            t3, t4 = (-hy - py) / uy, (hy - py) / uy
            tmin = np.maximum(np.minimum(t1, t2), np.minimum(t3, t4))
            tmax = np.minimum(np.maximum(t1, t2), np.maximum(t3, t4))
            hit = (tmax >= tmin) & (tmin > 0)
            best = np.where(hit & (tmin < best), tmin, best)
    return best


def outline(robot, step: float = 0.005) -> np.ndarray:
    """Points every ``step`` m on the robot's outline in base_link: the base plate's back edge to the magnet's
    face, as wide as the wheels' outer faces."""
    x0, x1 = -robot.base["size"][0] / 2, robot.electromagnet["x"]
    y1 = robot.track / 2 + robot.wheel.get("width", 0.0) / 2
    nx, ny = int(math.ceil((x1 - x0) / step)), int(math.ceil(2 * y1 / step))
    xs, ys = np.linspace(x0, x1, nx + 1), np.linspace(-y1, y1, ny + 1)
    return np.concatenate([np.stack([xs, np.full_like(xs, -y1)], 1), np.stack([xs, np.full_like(xs, y1)], 1),
                           np.stack([np.full_like(ys, x0), ys], 1), np.stack([np.full_like(ys, x1), ys], 1)])


def part_outline(part, step: float = 0.005) -> tuple[np.ndarray, np.ndarray]:
    """A part's outline (points every ``step`` m: its body, depth along local x with the plate's side at +x,
    width along y) and its feet (the body's lower corners, 5 mm in, SimTwo's), in the part's frame with the
    plate facing +x (the stand-in's ``facing`` convention; SimTwo's heading is facing + pi/2)."""
    hx, hy = part.depth / 2, part.width / 2
    xs = np.linspace(-hx, hx, int(math.ceil(2 * hx / step)) + 1)
    ys = np.linspace(-hy, hy, int(math.ceil(2 * hy / step)) + 1)
    pts = np.concatenate([np.stack([xs, np.full_like(xs, -hy)], 1), np.stack([xs, np.full_like(xs, hy)], 1),
                          np.stack([np.full_like(ys, -hx), ys], 1), np.stack([np.full_like(ys, hx), ys], 1)])
    r = 0.005
    feet = np.array([(sx * (hx - r), sy * (hy - r)) for sx in (-1, 1) for sy in (-1, 1)])
    return pts, feet


def part_boxes(part, poses) -> list:
    """Parts at (x, y, facing) as boxes (cx, cy, hx, hy, yaw) for :func:`clearance`'s ``boxes``."""
    return [(x, y, part.depth / 2, part.width / 2, f) for x, y, f in poses]


def clearance(field, robot, poses, boxes=(), shape=None) -> float:
    """The least distance (m) over the poses (x, y, theta) between the robot's outline and any box of the field
    (negative: inside it), or between its floor contacts (the wheels' outer edges, the caster) and the board's
    edge (SimTwo's field is a 1 mm board with no walls round it: only what touches the floor can leave it).
    ``boxes``: more obstacles, (cx, cy, hx, hy, yaw) each (other parts: :func:`part_boxes`); ``shape``: (outline,
    feet) instead of the robot's (a part: :func:`part_outline`, poses with its facing)."""
    if shape is None:
        pts = outline(robot)
        y1 = robot.track / 2 + robot.wheel.get("width", 0.0) / 2
        feet = np.array([(0.0, y1), (0.0, -y1), (robot.caster["x"], 0.0)])
    else:
        pts, feet = shape
    obstacles = [(b.center[0], b.center[1], b.size[0] / 2, b.size[1] / 2, b.yaw) for b in field.boxes]
    obstacles += list(boxes)
    best = math.inf
    for x, y, th in poses:
        c, s = math.cos(th), math.sin(th)
        wx, wy = x + pts[:, 0] * c - pts[:, 1] * s, y + pts[:, 0] * s + pts[:, 1] * c
        fx, fy = x + feet[:, 0] * c - feet[:, 1] * s, y + feet[:, 0] * s + feet[:, 1] * c
        best = min(best, float(np.min(fx - field.floor.x[0])), float(np.min(field.floor.x[1] - fx)),
                   float(np.min(fy - field.floor.y[0])), float(np.min(field.floor.y[1] - fy)))
        for cx, cy, hx, hy, yaw in obstacles:
            bc, bs = math.cos(yaw), math.sin(yaw)
            px = (wx - cx) * bc + (wy - cy) * bs
            py = -(wx - cx) * bs + (wy - cy) * bc
            qx, qy = np.abs(px) - hx, np.abs(py) - hy
            d = np.where((qx < 0) & (qy < 0), np.maximum(qx, qy), np.hypot(np.maximum(qx, 0), np.maximum(qy, 0)))
            best = min(best, float(np.min(d)))
    return best


# ------------------------------------------------------------------------------------------ one run
def one_run(simulator: str = "standin", camera: bool = True, plan: tuple | None = None, seed: int = 0,
            standin_args: tuple = (), carry: bool = False, trace: str | Path | None = None) -> dict:
    """One drive on ``simulator``; the figures of the module's docstring (keys with units). ``carry``: with
    Part1 on the magnet (:func:`carry_drive` unless ``plan`` is given; its first segment must rest for longer
    than CARRY_PLACE_S + the pull-in). ``trace``: write every frame's ground truth (robot, parts, encoders,
    magnet) and segment as JSON Lines there, to look at a run afterwards."""
    import zmq

    from ..field import load_field
    from ..localization.geometry import wrap_angle
    from ..localization.odometry import DiffDriveOdometry
    from ..robot import load_robot
    from ..simtwo import Command, SensorFrame
    from ..simtwo.teleport import SIMTWO_PART_PREFIX, SIMTWO_PART_Z, TeleportSender, part_heading

    if simulator not in SIMULATORS:
        raise ValueError(f"simulator {simulator!r}: one of {SIMULATORS}")
    plan = tuple(plan or (carry_drive() if carry else default_drive()))
    if carry and (plan[0].kind != "rest" or plan[0].seconds < CARRY_PLACE_S + 1.0):
        raise ValueError(f"a carry plan starts with a rest of at least {CARRY_PLACE_S + 1.0} s")
    sim = _StandIn(camera, seed, standin_args, carry) if simulator == "standin" else _SimTwo(camera)
    # SimTwo: the teleports (the robot to CARRY_START, then Part1) ride on the replies, as the bridge sends them
    teleports = TeleportSender() if carry and simulator == "simtwo" else None
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", sim.bridge_port))
    sock.settimeout(2.0)
    cam_times: list[float] = []
    stop = threading.Event()

    def camera_reader():
        sub = zmq.Context.instance().socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://127.0.0.1:{sim.camera_port}")
        try:
            while not stop.is_set():
                if sub.poll(100):
                    sub.recv()
                    cam_times.append(time.monotonic())
        finally:
            sub.close()

    robot = load_robot()
    odo = DiffDriveOdometry(robot, track=robot.track)  # the nominal track: the simulators' physics compared
    t0 = time.monotonic()
    out: dict = {}
    frames = []  # (arrival, SensorFrame)
    marks: dict[str, tuple] = {}  # segment -> (odometry pose, truth pose, unwrapped yaws, truth path) at its end
    ends: dict[str, int] = {}  # segment -> the index in frames of its last frame
    magnet, placed = False, None  # the carry: the magnet's command; (sim time, x, y, facing) of the part's teleport
    yaw = [0.0, 0.0]
    path = 0.0
    last = None
    try:
        sim.start()
        reader = threading.Thread(target=camera_reader, daemon=True)
        reader.start()
        end = time.monotonic() + 90
        while True:  # the first frame (the stand-in: its start; SimTwo: already streaming)
            try:
                data, addr = sock.recvfrom(65535)
                break
            except socket.timeout:
                sim.check()
                if time.monotonic() > end:
                    raise RuntimeError(f"no SensorFrame from {simulator} in 90 s")
        out["start_s"] = time.monotonic() - t0
        if sim.ready_s is not None:
            out["streaming_s"] = sim.ready_s
        status0 = len(sim.status())
        # segments last so many wall seconds; the carry's so many simulated seconds (SimTwo runs 6-11 % faster
        # than the wall clock: timed by the wall its drive overshot each segment, drifted 10-18 cm east of the
        # stand-in's route, put the held part's feet 1-3 cm over the board's south edge and in one run of three
        # caught machine A's rib with it)
        sim_clock = carry
        seg_end, i = (SensorFrame.decode(data).time if sim_clock else time.monotonic()) + plan[0].seconds, 0
        if teleports is not None:
            teleports.request(*CARRY_START)
        while i < len(plan):
            f = SensorFrame.decode(data)
            now = time.monotonic()
            frames.append((now, f))
            if (carry and placed is None and f.time - frames[0][1].time >= CARRY_PLACE_S
                    and (teleports is None or math.hypot(f.x - CARRY_START[0], f.y - CARRY_START[1]) < 0.02)):
                placed = _place_carried(sim, teleports, robot, f, SIMTWO_PART_Z, SIMTWO_PART_PREFIX, part_heading)
                magnet = True
            o = odo.update(f.enc_total[0], f.enc_total[1], f.time)
            pose_o, pose_g = (o.x, o.y, o.theta), (f.x, f.y, f.theta)
            if last is not None:
                yaw[0] += wrap_angle(pose_o[2] - last[0][2])
                yaw[1] += wrap_angle(pose_g[2] - last[1][2])
                path += math.hypot(pose_g[0] - last[1][0], pose_g[1] - last[1][1])
            last = (pose_o, pose_g)
            if (f.time if sim_clock else now) >= seg_end - (1e-6 if sim_clock else 0.0):
                if carry and placed is None:
                    raise RuntimeError(f"{simulator}: the robot not at the carry's start {CARRY_START[:2]} by the "
                                       f"end of {plan[0].name} but at ({f.x:.3f}, {f.y:.3f}): no teleport support?")
                marks[plan[i].name] = (pose_o, pose_g, tuple(yaw), path)
                ends[plan[i].name] = len(frames) - 1
                i += 1
                if i < len(plan):
                    seg_end += plan[i].seconds
            seg = plan[min(i, len(plan) - 1)]
            reply = Command(seg.v, seg.w, magnet, f.seq).encode()
            sock.sendto(reply + teleports.labels() if teleports is not None else reply, addr)
            if i < len(plan):
                data, addr = sock.recvfrom(65535)
        # the replies-applied share from the simulator's status lines (at least two after the drive began)
        deadline = time.monotonic() + (STATUS_EVERY * 0.04 * 2 + 5 if simulator == "simtwo" else 5)
        while len(sim.status()) < status0 + 2 and time.monotonic() < deadline:
            _reply_idle(sock)
        lines = sim.status()[status0:]
        if len(lines) >= 2:
            (f0, a0, *_), (f1, a1, *rest) = lines[0], lines[-1]
            out["replies_applied_share"] = (a1 - a0) / (f1 - f0)
            if rest:
                out["replies_ignored"] = rest[0]
    finally:
        stop.set()
        sock.close()
        sim.stop()
    field = load_field(FIELD)
    if trace is not None:
        _write_trace(trace, frames, plan, ends)
    out.update(_rates(frames, cam_times, camera))
    out.update(_lidar(frames, robot, field, plan, marks, carry))
    out.update(_odometry(plan, marks))
    poses = [(f.x, f.y, f.theta) for _, f in frames[::5]]
    if not carry:
        out["clearance_min_m"] = clearance(field, robot, poses)
        return out
    if simulator == "standin" and not (sim.placed or {}).get("ok"):
        raise RuntimeError(f"the stand-in did not place part {CARRY_PART}: {sim.placed}")
    # the other parts where they stood at the start (as obstacles); the carried one from the frames
    others = [(x, y, th - math.pi / 2) for k, (x, y, th) in enumerate(frames[0][1].parts) if k != CARRY_PART - 1]
    obstacles = part_boxes(field.part, others)
    start = ends[plan[0].name]
    out["clearance_min_m"] = clearance(field, robot, poses[start // 5:], obstacles)
    out["carry_part_clearance_min_m"] = clearance(
        field, robot, [(p[0], p[1], p[2] - math.pi / 2) for _, f in frames[start::5] for p in f.parts[:1]],
        obstacles, part_outline(field.part))
    out.update(_carry(frames, plan, ends, robot, field, placed))
    return out


def _write_trace(path, frames, plan, ends) -> None:
    import json

    seg_of = []
    for s in plan:
        seg_of += [s.name] * (ends.get(s.name, len(frames) - 1) + 1 - len(seg_of))
    with open(path, "w", encoding="utf-8") as fh:
        for k, (wall, f) in enumerate(frames):
            fh.write(json.dumps({"seq": f.seq, "t": f.time, "wall": round(wall - frames[0][0], 4),
                                 "seg": seg_of[k] if k < len(seg_of) else plan[-1].name,
                                 "pose": [f.x, f.y, f.theta], "enc": list(f.enc_total), "magnet": f.magnet,
                                 "contact": f.contact, "parts": [list(p) for p in f.parts]}) + "\n")


def _place_carried(sim, teleports, robot, f, part_z, prefix, part_heading):
    """Put the carried part CARRY_GAP_M short of where a held part sits in front of the robot's ground truth
    ``f`` (a SensorFrame), plate towards the robot: SimTwo by a teleport in the next replies, the stand-in by its
    control channel. Returns (sim time, x, y, facing)."""
    from ..field import load_field

    d = held_x(robot, load_field(FIELD)) + CARRY_GAP_M
    x, y, facing = f.x + d * math.cos(f.theta), f.y + d * math.sin(f.theta), f.theta + math.pi
    if teleports is not None:
        teleports.request(x, y, part_heading(facing), part_z, f"{prefix}{CARRY_PART}")
    else:
        sim.place_part(CARRY_PART, x, y, math.remainder(facing, 2 * math.pi))
    return f.time, x, y, facing


def held_x(robot, field) -> float:
    """Where a held part's centre sits, m ahead of base_link: the magnet's face + the part's depth / 2 (as
    competition/live.py's LiveReferee.held_x)."""
    return float(robot.electromagnet["x"]) + field.part.depth / 2


def carry_offsets(frames, robot, field) -> np.ndarray:
    """Per frame: sim time (s), the carried part's offset from the held position along and across the robot
    (m, in base_link), its rotation against the robot (rad; 0: plate flat on the face), and its distance from the
    held position (m). From the SensorFrame's ground truth and Parts (SimTwo's heading: the plate's + pi/2)."""
    hx = held_x(robot, field)
    rows = []
    for _, f in frames:
        if len(f.parts) < CARRY_PART:
            rows.append((f.time, np.nan, np.nan, np.nan, np.nan))
            continue
        px, py, ph = f.parts[CARRY_PART - 1]
        c, s = math.cos(f.theta), math.sin(f.theta)
        dx, dy = px - f.x, py - f.y
        along, across = dx * c + dy * s - hx, -dx * s + dy * c
        rot = math.remainder((ph - math.pi / 2) - (f.theta + math.pi), 2 * math.pi)
        rows.append((f.time, along, across, rot, math.hypot(along, across)))
    return np.array(rows, dtype=float)


def _carry(frames, plan, ends, robot, field, placed) -> dict:
    """The carry's figures (module docstring): the grip at settle's end, per segment and over the carry."""
    a = carry_offsets(frames, robot, field)
    t, along, across, rot, dist = a.T
    out = {}
    i0 = ends[plan[0].name]
    k = np.flatnonzero(t >= placed[0])
    # pulled in: the first frame from which the part stays within 1 mm (along) of where it rests at settle's end
    after = np.arange(k[0], i0 + 1)
    off = np.abs(along[after] - along[i0]) > 0.001
    out["carry_pull_in_s"] = float(t[after[np.flatnonzero(off)[-1] + 1]] - placed[0]) if off.any() else 0.0
    out["carry_grip_along_mm"] = 1000 * float(along[i0])
    out["carry_grip_across_mm"] = 1000 * float(across[i0])
    out["carry_grip_rot_deg"] = math.degrees(float(rot[i0]))
    out["carry_gripped"] = float(dist[i0] < 0.01)

    def figures(prefix, lo, hi):
        sl = slice(lo + 1, hi + 1)
        out[f"{prefix}_part_along_max_mm"] = 1000 * float(np.nanmax(np.abs(along[sl])))
        out[f"{prefix}_part_across_max_mm"] = 1000 * float(np.nanmax(np.abs(across[sl])))
        out[f"{prefix}_part_rot_max_deg"] = math.degrees(float(np.nanmax(np.abs(rot[sl]))))
        out[f"{prefix}_part_along_mm"] = 1000 * float(along[hi])
        out[f"{prefix}_part_across_mm"] = 1000 * float(across[hi])
        out[f"{prefix}_part_rot_deg"] = math.degrees(float(rot[hi]))

    names = [s.name for s in plan]
    for prev, seg in zip(names[:-1], names[1:]):
        figures(seg, ends[prev], ends[seg])
    figures("carry", i0, ends[names[-1]])
    lost = np.flatnonzero(dist[i0 + 1:ends[names[-1]] + 1] > CARRY_LOST_M)
    out["carry_lost"] = float(lost.size > 0)
    if lost.size:
        j = i0 + 1 + int(lost[0])
        out["carry_lost_at_s"] = float(t[j] - t[i0])
        seg = next(n for n in names[1:] if ends[n] >= j)
        out[f"carry_lost_in_{seg}"] = 1.0
    return out


def _reply_idle(sock) -> None:
    """Keep answering (stopped) while waiting for a status line."""
    from ..simtwo import Command, SensorFrame

    try:
        data, addr = sock.recvfrom(65535)
    except socket.timeout:
        return
    sock.sendto(Command(0.0, 0.0, False, SensorFrame.decode(data).seq).encode(), addr)


RATE_SKIP_S = 2.0  # wall s at the start left out of the rates: the frames queued while the simulator started


def _rates(frames, cam_times, camera: bool) -> dict:
    """Rates over the run after its first RATE_SKIP_S wall seconds: the socket is bound before the simulator
    starts, so what it sent meanwhile (SimTwo: while its camera window opened) arrives in one burst, which
    would count as frames per wall second (SimTwo 1.06-1.14x instead of 1.02x)."""
    out = {}
    t0 = frames[0][0] + RATE_SKIP_S
    frames = [f for f in frames if f[0] >= t0] if frames[-1][0] - frames[0][0] > 2 * RATE_SKIP_S else frames
    wall = frames[-1][0] - frames[0][0]
    sim_s = frames[-1][1].time - frames[0][1].time
    out["frames_per_s_wall"] = (len(frames) - 1) / wall
    out["frames_per_s_sim"] = (len(frames) - 1) / sim_s
    out["sim_time_per_wall_time"] = sim_s / wall
    cams = [t for t in cam_times if frames[0][0] <= t <= frames[-1][0]]
    out["camera_frames_per_s"] = len(cams) / wall if camera else 0.0
    if cams:
        # a camera frame shows the scene at or after the SensorFrame before it: the wall time from that
        # SensorFrame's arrival to the camera frame's is an upper bound of the camera's latency
        arrivals = [t for t, _ in frames]
        after = sorted(1000 * (c - arrivals[bisect.bisect_right(arrivals, c) - 1]) for c in cams)
        out["camera_after_sensorframe_ms"] = statistics.median(after)
        out["camera_after_sensorframe_p90_ms"] = after[int(0.9 * (len(after) - 1))]
    return out


def _lidar(frames, robot, field, plan, marks, carry: bool = False) -> dict:
    """Sweeps per second, self hits per sweep, range error against the field's boxes at the truth pose.
    ``carry``: returns in front of the magnet where the held part stands (even turned by 30 deg) are left out of
    the error."""
    from ..sim.sensors import simtwo_ray_steps
    from ..simtwo.selfhits import Footprint

    lid = robot.lidar
    angles = lid.angles()
    steps = np.asarray(simtwo_ray_steps(lid.rays, lid.period, robot.physics_step), dtype=float)
    fp = Footprint.from_robot(robot)
    boxes = field_boxes(field, lid.xyz[2])
    times = np.array([f.time for _, f in frames])
    truth = np.array([(f.x, f.y, f.theta) for _, f in frames])
    truth[:, 2] = np.unwrap(truth[:, 2])
    # the truth's segment at each frame time: at rest = in a rest segment and settled 0.5 s
    rest_spans, t = [], frames[0][1].time
    for seg in plan:
        if seg.kind == "rest" and seg.name in marks:
            rest_spans.append((t + 0.5, t + seg.seconds))
        t += seg.seconds
    sweeps, self_hits, err_rest, err_moving = 0, [], [], []
    prev = None
    for k, (_, f) in enumerate(frames):
        r = np.asarray(f.ranges, dtype=float)
        if r.size != lid.rays or not np.any(r != 0) or (prev is not None and np.array_equal(r, prev)):
            prev = r
            continue
        prev = r
        sweeps += 1
        ok = r > 0
        # each ray's measuring instant (SimTwo's schedule; the stand-in repeats it): ray i at Tms - 0.239 + j_i ms
        tr = f.time - 0.239 + steps * robot.physics_step
        x = np.interp(tr, times, truth[:, 0])
        y = np.interp(tr, times, truth[:, 1])
        th = np.interp(tr, times, truth[:, 2])
        hx, hy = lid.xyz[0] + r * np.cos(angles), lid.xyz[1] + r * np.sin(angles)  # in base_link
        self_hits.append(int(np.sum(ok & fp.contains(hx, hy))))
        ox = x + lid.xyz[0] * np.cos(th) - lid.xyz[1] * np.sin(th)
        oy = y + lid.xyz[0] * np.sin(th) + lid.xyz[1] * np.cos(th)
        expect = cast(boxes, ox, oy, np.cos(th + angles), np.sin(th + angles))
        use = ok & ~fp.contains(hx, hy) & np.isfinite(expect) & (expect < 1.5)
        if carry:
            ex, part = float(robot.electromagnet["x"]), field.part
            use &= ~((hx > ex - 0.01) & (hx < ex + part.depth + 0.05) & (np.abs(hy) < part.width / 2 + 0.025))
        err = (r - expect)[use]
        at_rest = any(a <= tr[0] and tr[-1] <= b for a, b in rest_spans)
        (err_rest if at_rest else err_moving).append(err)
    sim_s = frames[-1][1].time - frames[0][1].time
    wall = frames[-1][0] - frames[0][0]
    out = {"lidar_sweeps_per_s_sim": sweeps / sim_s, "lidar_sweeps_per_s_wall": sweeps / wall}
    if self_hits:
        out["lidar_self_hits_per_sweep"] = float(np.mean(self_hits))
    for name, errs in (("rest", err_rest), ("moving", err_moving)):
        if errs and sum(e.size for e in errs):
            e = np.concatenate(errs)
            out[f"lidar_wall_error_{name}_mm_median"] = 1000 * float(np.median(e))
            out[f"lidar_wall_abs_error_{name}_mm_median"] = 1000 * float(np.median(np.abs(e)))
            out[f"lidar_wall_within_20mm_{name}_share"] = float(np.mean(np.abs(e) < 0.02))
    return out


def _odometry(plan, marks) -> dict:
    """Per segment (from the end of the one before) and over the whole drive (settle's end -> stop's end)."""
    from ..localization.geometry import between2

    out = {}
    names = [s.name for s in plan]
    for a, seg in zip(names[:-1], plan[1:]):
        b = seg.name
        (oa, ga, ya, pa), (ob, gb, yb, pb) = marks[a], marks[b]
        ro, rg = between2(oa, ob), between2(ga, gb)
        turn_o, turn_g = yb[0] - ya[0], yb[1] - ya[1]  # unwrapped heading changes over the segment
        out[f"{b}_truth_turn_deg"] = math.degrees(turn_g)
        out[f"{b}_odom_minus_truth_turn_deg"] = math.degrees(turn_o - turn_g)
        walked = pb - pa
        if seg.kind in ("straight", "arc"):
            out[f"{b}_truth_m"] = walked
            out[f"{b}_odom_error_mm_per_m"] = 1000 * math.hypot(ro[0] - rg[0], ro[1] - rg[1]) / walked
        if seg.kind == "straight":
            d = math.hypot(rg[0], rg[1])
            out[f"{b}_odom_over_truth"] = math.hypot(ro[0], ro[1]) / d
        if seg.kind == "spin" and turn_o:
            out[f"{b}_truth_over_odom_turn"] = turn_g / turn_o
    (o0, g0, _, p0), (o1, g1, _, p1) = marks[names[0]], marks[names[-1]]
    ro, rg = between2(o0, o1), between2(g0, g1)
    err = math.hypot(ro[0] - rg[0], ro[1] - rg[1])
    out["odom_error_mm"] = 1000 * err
    out["odom_error_mm_per_m"] = 1000 * err / (p1 - p0)
    out["odom_heading_error_deg"] = abs(math.degrees(math.remainder(ro[2] - rg[2], 2 * math.pi)))
    return out


# ------------------------------------------------------------------------------------------ the command
def add_arguments(parser) -> None:
    parser.add_argument("--simulator", choices=SIMULATORS, default="standin",
                        help="standin: raf sim, real time, its SimTwo-like defaults (default); simtwo: the real "
                             "SimTwo (raf simtwo build first; wrap it in flock /tmp/raf-simtwo.lock when "
                             "others measure SimTwo too)")
    parser.add_argument("--repeats", type=int, default=2, help="runs (default 2)")
    parser.add_argument("--no-camera", action="store_true", help="without the camera")
    parser.add_argument("--carry", action="store_true",
                        help="pick and carry: Part1 teleported in front of the magnet, switched on, the same "
                             "segments from 75 mm further east; adds the part's offset, rotation and losses")
    parser.add_argument("--trace-dir", default=None, metavar="DIR",
                        help="write each run's frames (ground truth, parts, encoders) to DIR/drive_<sim>_<k>.jsonl")
    parser.add_argument("--sim-arg", action="append", default=[], metavar="ARG",
                        help="an extra argument for raf sim (stand-in only; repeat, e.g. --sim-arg=--pid-timing "
                             "--sim-arg=scene_enabled)")


def summarise(runs: list[dict], head: dict) -> dict:
    """min / median / max of every figure over the runs."""
    out = dict(head, runs=len(runs))
    keys = list(dict.fromkeys(k for r in runs for k in r))
    for key in keys:
        vals = [r[key] for r in runs if key in r]
        out[f"{key}_median"] = statistics.median(vals)
        out[f"{key}_min"] = min(vals)
        out[f"{key}_max"] = max(vals)
    return out


def _trace_path(args, k: int):
    if not getattr(args, "trace_dir", None):
        return None
    d = Path(args.trace_dir)
    d.mkdir(parents=True, exist_ok=True)
    return d / f"{'carry' if args.carry else 'drive'}_{args.simulator}_{k + 1}.jsonl"


def run(args) -> dict:
    runs = []
    for k in range(args.repeats):
        print(f"[bench drive] {args.simulator}: run {k + 1} of {args.repeats}", flush=True)
        runs.append(one_run(args.simulator, not args.no_camera, seed=k, standin_args=tuple(args.sim_arg),
                            carry=args.carry, trace=_trace_path(args, k)))
        if args.carry:
            r = runs[-1]
            lost = [n[len("carry_lost_in_"):] for n in r if n.startswith("carry_lost_in_")]
            print(f"[bench drive]   carry: grip along {r['carry_grip_along_mm']:.1f} mm, max across "
                  f"{r['carry_part_across_max_mm']:.1f} mm, max rotation {r['carry_part_rot_max_deg']:.1f} deg, "
                  + (f"lost in {lost[0]} at {r['carry_lost_at_s']:.2f} s" if lost else "held"), flush=True)
    return summarise(runs, {"simulator": args.simulator, "camera": not args.no_camera, "carry": args.carry,
                            "sim_args": " ".join(args.sim_arg) if args.simulator == "standin" else ""})
