"""``raf bench simtwo``: the real SimTwo (the Linux build) measured without ROS, over repeated runs.

Each run: ``raf simtwo run``'s SimTwoRun (camera open), a scripted bridge in this process that answers every
SensorFrame at once (settle 2 s, 0.6 m straight at 0.2 m/s, half a turn on the spot at 1.5 rad/s or
``--spin-rate``, 0.5 m straight, stop), and from what SimTwo itself sends or prints: frame rate, SimTwo's
clock against the wall clock, the share of cycles in which SimTwo applied a reply (control.pas's status line),
camera frames per second and how long after the SensorFrame before it each arrives (an upper bound of the
camera's latency: the image shows the scene at or after that frame), and odometry (the encoders' totals
through the project's DiffDriveOdometry) against SimTwo's ground truth, over the whole drive and per segment.
Ranges are min-max over the runs.
"""
from __future__ import annotations

import bisect
import math
import re
import socket
import statistics
import tempfile
import threading
import time
from pathlib import Path

NAME = "simtwo"
HELP = "the real SimTwo on Linux: rates, replies applied, camera, odometry against its ground truth (no ROS)"
TARGETS = {"frames_per_s_sim_median": "25 (SimTwo's 40 ms script period)",
           "replies_applied_share_min": "> 0.45 (SimTwo's GUI loop: docs/simtwo.md)"}
STATUS_EVERY = 125
SPIN_RATE = 1.5  # rad/s: half a turn on the spot in 2.1 s


def drive(spin_rate: float = SPIN_RATE) -> tuple:
    """The scripted drive: (segment, seconds, V m/s, W rad/s); half a turn on the spot at ``spin_rate``."""
    return (("settle", 2.0, 0.0, 0.0), ("straight", 3.0, 0.2, 0.0), ("spin", math.pi / spin_rate, 0.0, spin_rate),
            ("back", 2.5, 0.2, 0.0), ("stop", 1.5, 0.0, 0.0))


def add_arguments(parser) -> None:
    parser.add_argument("--repeats", type=int, default=2, help="SimTwo runs (default 2)")
    parser.add_argument("--no-camera", action="store_true", help="do not open SimTwo's camera")
    parser.add_argument("--spin-rate", type=float, default=SPIN_RATE, metavar="RAD_S",
                        help=f"the turn on the spot's rate (default {SPIN_RATE})")


def _script(tmp: Path) -> Path:
    from ..simtwo_linux.scene import SIMTWO_DIR

    text = (SIMTWO_DIR / "control.pas").read_text(encoding="latin-1")
    text = re.sub(r"^(\s*STATUS_EVERY\s*=\s*)\d+;", rf"\g<1>{STATUS_EVERY};", text, count=1, flags=re.M)
    (tmp / "control.pas").write_text(text, encoding="latin-1")
    return tmp / "control.pas"




def one_run(camera: bool, spin_rate: float = SPIN_RATE) -> dict:
    import zmq

    from ..localization.geometry import between2, wrap_angle
    from ..localization.odometry import DiffDriveOdometry
    from ..robot import load_robot
    from ..simtwo import Command, SensorFrame
    from ..simtwo_linux import build
    from ..simtwo_linux.run import Ports, SimTwoRun

    tmp = Path(tempfile.mkdtemp(prefix="raf-bench-simtwo-"))
    ports = Ports.free()
    run = SimTwoRun(build.require(), ports, camera=camera, script=_script(tmp))
    t0 = time.monotonic()
    run.start()
    out = {"streaming_s": run.ready_s, "start_s": time.monotonic() - t0}
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", ports.bridge))
    sock.settimeout(2.0)
    cam_times: list[float] = []  # arrival of each camera frame (monotonic)
    stop = threading.Event()

    def camera_reader():
        sub = zmq.Context.instance().socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.setsockopt(zmq.LINGER, 0)
        sub.connect(f"tcp://127.0.0.1:{ports.camera}")
        try:
            while not stop.is_set():
                if sub.poll(100):
                    sub.recv()
                    cam_times.append(time.monotonic())
        finally:
            sub.close()

    reader = threading.Thread(target=camera_reader, daemon=True)
    reader.start()
    odo = DiffDriveOdometry(load_robot())
    plan = drive(spin_rate)
    marks: dict[str, tuple] = {}  # segment -> (odometry pose, truth pose, unwrapped yaws) at its end
    yaw = [0.0, 0.0]  # odometry's and the truth's heading, unwrapped (a half turn wraps at +-180 deg)
    last = None
    frames = []
    try:
        status0 = len(re.findall(r"replies applied", run.log_text()))
        start = time.monotonic()
        seg_end, i = start + plan[0][1], 0
        while i < len(plan):
            data, addr = sock.recvfrom(65535)
            f = SensorFrame.decode(data)
            now = time.monotonic()
            frames.append((now, f.time))
            o = odo.update(f.enc_total[0], f.enc_total[1], f.time)
            pose_o, pose_g = (o.x, o.y, o.theta), (f.x, f.y, f.theta)
            if last is not None:
                yaw[0] += wrap_angle(pose_o[2] - last[0][2])
                yaw[1] += wrap_angle(pose_g[2] - last[1][2])
            last = (pose_o, pose_g)
            if now >= seg_end:
                marks[plan[i][0]] = (pose_o, pose_g, tuple(yaw))
                i += 1
                if i < len(plan):
                    seg_end += plan[i][1]
            _name, _, v, w = plan[min(i, len(plan) - 1)]
            sock.sendto(Command(v, w, False, f.seq).encode(), addr)
        wall = frames[-1][0] - frames[0][0]
        out["frames_per_s_wall"] = (len(frames) - 1) / wall
        out["frames_per_s_sim"] = (len(frames) - 1) / (frames[-1][1] - frames[0][1])
        out["sim_time_per_wall_time"] = (frames[-1][1] - frames[0][1]) / wall
        cams = [t for t in cam_times if frames[0][0] <= t <= frames[-1][0]]
        out["camera_frames_per_s"] = len(cams) / wall if camera else 0.0
        if cams:
            # a camera frame shows the scene at or after the SensorFrame before it: the wall time from that
            # SensorFrame's arrival to the camera frame's is an upper bound of the camera's latency
            arrivals = [t for t, _ in frames]
            after = sorted(1000 * (c - arrivals[bisect.bisect_right(arrivals, c) - 1]) for c in cams)
            out["camera_after_sensorframe_ms"] = statistics.median(after)
            out["camera_after_sensorframe_p90_ms"] = after[int(0.9 * (len(after) - 1))]
        deadline = time.monotonic() + STATUS_EVERY * 0.04 * 2 + 5
        pat = re.compile(r"frames (\d+), replies applied (\d+), ignored (\d+)")
        while len(pat.findall(run.log_text())) < status0 + 2 and time.monotonic() < deadline:
            _reply_idle(sock)
        lines = [tuple(map(int, x)) for x in pat.findall(run.log_text())][status0:]
        if len(lines) >= 2:
            (f0, a0, _), (f1, a1, i1) = lines[0], lines[-1]
            out["replies_applied_share"] = (a1 - a0) / (f1 - f0)
            out["replies_ignored"] = i1
    finally:
        stop.set()
        reader.join(2.0)
        sock.close()
        run.stop()
    # odometry against the truth: whole drive (settle end -> stop end) and per segment
    names = [d[0] for d in drive(spin_rate)]
    path = 0.0
    for a, b in zip(names[:-1], names[1:]):
        (oa, ga, ya), (ob, gb, yb) = marks[a], marks[b]
        ro, rg = between2(oa, ob), between2(ga, gb)
        turn_o, turn_g = yb[0] - ya[0], yb[1] - ya[1]  # unwrapped heading changes over the segment
        out[f"{b}_truth_turn_deg"] = math.degrees(turn_g)
        out[f"{b}_odom_minus_truth_turn_deg"] = math.degrees(turn_o - turn_g)
        if b in ("straight", "back"):
            d = math.hypot(rg[0], rg[1])
            path += d
            out[f"{b}_truth_m"] = d
            out[f"{b}_odom_over_truth"] = math.hypot(ro[0], ro[1]) / d
    (o0, g0, _), (o1, g1, _) = marks["settle"], marks["stop"]
    ro, rg = between2(o0, o1), between2(g0, g1)
    err = math.hypot(ro[0] - rg[0], ro[1] - rg[1])
    out["odom_error_mm"] = 1000 * err
    out["odom_error_mm_per_m"] = 1000 * err / path
    out["odom_heading_error_deg"] = abs(math.degrees(math.remainder(ro[2] - rg[2], 2 * math.pi)))
    return out


def _reply_idle(sock) -> None:
    """Keep answering (stopped) while waiting for SimTwo's status line."""
    from ..simtwo import Command, SensorFrame

    try:
        data, addr = sock.recvfrom(65535)
    except socket.timeout:
        return
    sock.sendto(Command(0.0, 0.0, False, SensorFrame.decode(data).seq).encode(), addr)


def run(args) -> dict:
    runs = []
    for k in range(args.repeats):
        print(f"[bench simtwo] run {k + 1} of {args.repeats}", flush=True)
        runs.append(one_run(not args.no_camera, args.spin_rate))
    out: dict = {"runs": len(runs), "camera": not args.no_camera, "spin_rate_rad_per_s": args.spin_rate}
    for key in runs[0]:
        vals = [r[key] for r in runs if key in r]
        out[f"{key}_median"] = statistics.median(vals)
        out[f"{key}_min"] = min(vals)
        out[f"{key}_max"] = max(vals)
    return out
