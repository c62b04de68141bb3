"""``raf bench bridge``: latency and throughput of the ROS bridge, with real processes, on ROS 1 and ROS 2.

Per middleware (``--middlewares ros1,ros2``; default: each one whose environment exists), the measuring part
(:func:`measure`) runs in that middleware's interpreter (``.venv`` / ``.venv-ros2``, see
:func:`robotatfactory.ros.processes.interpreter`) as a subprocess, one after the other in one invocation
(``--repeats N``: N rounds, the middlewares alternating, so that both see the same machine load). Keys are
prefixed with the middleware (``ros1_odom_latency_p99_ms``, ``ros2_camera_max_frames_per_s``, ...); with
repeats each key is the median over the runs and the headline figures also list every run (``..._runs``).

What one measurement does. A dedicated sender (the measuring process, no physics) plays the simulator:
SensorFrames over UDP and camera frames over ZMQ; a private graph (ROS 1: a roscore on a free port; ROS 2: a
domain id of its own), the real bridge node (``raf bridge``, its own process) and two subscriber processes
(``bench/_bridge_sub.py``): one for odom (a controller), one for images (a vision node). All processes read the
same system-wide monotonic clock, so a datagram's send time and the subscriber's receive time compare
directly. QoS as the nodes state it (:mod:`robotatfactory.ros.mw`): odom reliable (ROS 1: ``tcp_nodelay``),
the camera best effort on ROS 2 (``QoS.SENSOR``).

Phase 1a (control path alone) and 1b (the same with camera frames at ``--camera-fps``, each published just
before its cycle's SensorFrame, as SimTwo does): SensorFrames at ``--rate`` Hz; measured (a) the reply
round trip, SensorFrame sent -> Command back at the sender (what a lockstep simulator waits for), (b)
SensorFrame sent -> the odom subscriber's callback, (c) in 1b, camera frame sent -> the image subscriber's
callback. Phase 2 (throughput): camera frames as fast as the sender can for ``--camera-seconds``; the rate
at which images reach the subscriber is the highest sustained frame rate through the bridge (the bridge
keeps only the newest frame, so excess frames are dropped, not queued). The p99 target is checked on 1a;
1b shows what camera traffic costs the control path on the same cores.
"""
from __future__ import annotations

import json
import os
import shlex
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

NAME = "bridge"
HELP = ("bridge latency (datagram -> Command reply, datagram -> odom subscriber, camera -> image subscriber) and "
        "camera throughput, on ROS 1 and ROS 2 side by side")
MIDDLEWARES = ("ros1", "ros2")
#: per middleware: key -> target
TARGETS = {f"{m}_{k}": v for m in MIDDLEWARES for k, v in {
    "odom_latency_p99_ms": "<= 2 ms (issues 4, 13: control path p99)",
    "camera_max_frames_per_s": ">= 100 frames/s sustained (issues 4, 13)",
}.items()}
#: the figures printed side by side and listed per run with --repeats
HEADLINE = ("odom_latency_median_ms", "odom_latency_p99_ms", "odom_latency_max_ms", "odom_latency_p99_with_camera_ms",
            "reply_rtt_median_ms", "reply_rtt_p99_ms", "camera_latency_median_ms", "camera_latency_p99_ms",
            "camera_max_frames_per_s")


def add_arguments(parser) -> None:
    parser.add_argument("--rate", type=float, default=100.0, help="SensorFrames per second in phase 1 (default 100)")
    parser.add_argument("--seconds", type=float, default=10.0, help="length of phases 1a and 1b (default 10 s each)")
    parser.add_argument("--camera-seconds", type=float, default=5.0, help="length of phase 2 (default 5 s)")
    parser.add_argument("--camera-fps", type=float, default=15.0, help="camera rate in phase 1b (default 15)")
    parser.add_argument("--middlewares", default=None, metavar="ros1,ros2",
                        help="the middlewares to measure, one after the other (default: every one whose "
                             "environment exists: .venv for ros1, .venv-ros2 for ros2)")
    parser.add_argument("--bridge-args", default="", metavar="ARGS",
                        help="more arguments for raf bridge, one string, given with = (e.g. --bridge-args=--no-sim-time): "
                             "to measure a variant; the results name them")
    parser.add_argument("--repeats", type=int, default=1,
                        help="rounds of measurements (default 1); figures are medians, the headline ones also "
                             "listed per run")


def _measure_options(args) -> list[str]:
    return ["--rate", str(args.rate), "--seconds", str(args.seconds), "--camera-seconds", str(args.camera_seconds),
            "--camera-fps", str(args.camera_fps), f"--bridge-args={args.bridge_args or ''}"]


def middlewares_to_measure(spec: str | None) -> list[str]:
    """The middlewares named by ``spec`` (comma separated), or every one whose interpreter exists."""
    from ..errors import ConfigError
    from ..ros.processes import interpreter

    if spec:
        want = [m.strip().lower() for m in spec.split(",") if m.strip()]
        bad = [m for m in want if m not in MIDDLEWARES]
        if bad or not want:
            raise ConfigError(f"--middlewares {spec!r}: a comma-separated list of {', '.join(MIDDLEWARES)}")
        missing = [m for m in want if interpreter(m) is None]
        if missing:
            raise ConfigError(f"--middlewares: no environment for {', '.join(missing)} (scripts/bootstrap.sh builds "
                              ".venv for ros1 and .venv-ros2 for ros2)")
        return list(dict.fromkeys(want))
    have = [m for m in MIDDLEWARES if interpreter(m) is not None]
    if not have:
        raise ConfigError("neither ROS environment exists (.venv with rospy, .venv-ros2 with rclpy): run "
                          "scripts/bootstrap.sh")
    return have


def run(args) -> dict:
    from ..errors import ConfigError

    if args.repeats < 1:
        raise ConfigError("--repeats must be >= 1")
    mws = middlewares_to_measure(args.middlewares)
    runs: dict[str, list[dict]] = {m: [] for m in mws}
    for i in range(args.repeats):
        for m in mws:
            print(f"raf bench bridge: {m}, run {i + 1} of {args.repeats} ...", file=sys.stderr, flush=True)
            runs[m].append(measure_in(m, args))
    out = combine(runs)
    print(side_by_side(out, mws, args.repeats))
    return out


def measure_in(middleware: str, args) -> dict:
    """One :func:`measure` in ``middleware``'s interpreter (a subprocess); its result dict."""
    from ..ros.processes import interpreter

    py = interpreter(middleware)
    with tempfile.TemporaryDirectory(prefix="raf-bench-bridge-") as d:
        out = Path(d) / "result.json"
        env = dict(os.environ, RAF_MIDDLEWARE=middleware, PYTHONUNBUFFERED="1")
        cmd = [str(py), "-m", "robotatfactory.bench.bridge", "--out", str(out), *_measure_options(args)]
        budget = 180 + 2 * args.seconds + args.camera_seconds
        r = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=budget)
        if r.returncode != 0 or not out.is_file():
            tail = r.stdout.decode(errors="replace").splitlines()[-20:]
            raise RuntimeError(f"the {middleware} measurement failed (exit {r.returncode}):\n" + "\n".join(tail))
        return json.loads(out.read_text())


def combine(runs: dict[str, list[dict]]) -> dict:
    """Per-middleware keys: the median over the runs (numbers), the value of the last run (others); targets
    judged on the medians; the headline figures listed per run when there are several."""
    out: dict = {}
    for m, rs in runs.items():
        n = len(rs)
        keys = list(dict.fromkeys(k for r in rs for k in r))
        for k in keys:
            vals = [r.get(k) for r in rs]
            nums = [float(v) for v in vals if isinstance(v, (int, float)) and not isinstance(v, bool) and v is not None]
            if k.endswith("_target_met"):
                continue
            if nums and len(nums) == len(vals):
                med = float(np.median(nums))
                out[f"{m}_{k}"] = int(med) if all(isinstance(v, int) for v in vals) and med == int(med) else med
            else:
                out[f"{m}_{k}"] = vals[-1]
            if n > 1 and k in HEADLINE and nums:
                out[f"{m}_{k}_runs"] = " / ".join(f"{v:.2f}" for v in nums)
        p99, fps = out.get(f"{m}_odom_latency_p99_ms"), out.get(f"{m}_camera_max_frames_per_s")
        out[f"{m}_runs"] = n
        out[f"{m}_odom_p99_target_met"] = p99 is not None and p99 == p99 and p99 <= 2.0
        out[f"{m}_camera_rate_target_met"] = fps is not None and fps >= 100.0
    return out


def side_by_side(out: dict, mws: list[str], repeats: int) -> str:
    """A Markdown table: one row per headline figure, one column per middleware."""
    from ..results import _fmt

    head = "| figure | " + " | ".join(mws) + " |"
    rows = [f"raf bench bridge, {repeats} run(s) per middleware (medians; per run in brackets)", head,
            "|---|" + "---|" * len(mws)]
    for k in HEADLINE:
        cells = []
        for m in mws:
            v = out.get(f"{m}_{k}")
            runs_ = out.get(f"{m}_{k}_runs")
            cells.append("-" if v is None else _fmt(v) + (f" ({runs_})" if runs_ else ""))
        rows.append(f"| `{k}` | " + " | ".join(cells) + " |")
    for k in ("odom_p99_target_met", "camera_rate_target_met"):
        rows.append(f"| `{k}` | " + " | ".join(str(out.get(f"{m}_{k}")) for m in mws) + " |")
    return "\n".join(rows) + "\n"


# ------------------------------------------------------------------------------ one measurement (one middleware)


def measure(args) -> dict:
    """The measurement on this process's middleware (see the module's docstring); a flat dict, unprefixed."""
    import zmq

    from ..ros.master import free_port, private_graph
    from ..ros.mw import name as middleware
    from ..ros.processes import Procs, raf_cmd
    from ..simtwo import Command, ProtocolError, SensorFrame, encode_frame
    from .protocol import sample_frame

    tmp = Path(tempfile.mkdtemp(prefix="raf-bench-bridge-"))
    graph = private_graph(middleware()).start()
    env = graph.env()
    port = free_port(socket.SOCK_DGRAM)
    cam_port = free_port()
    procs = Procs(tmp)
    try:
        procs.start("bridge", raf_cmd("bridge", "--port", str(port), "--camera", f"tcp://127.0.0.1:{cam_port}",
                                      "--set", "watchdog/timeout=1000", *shlex.split(args.bridge_args or "")), env)
        for what in ("odom", "image"):
            procs.start(f"sub_{what}", [sys.executable, "-m", "robotatfactory.bench._bridge_sub",
                                        str(tmp / f"sub_{what}.json"), what], env)

        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        ctx = zmq.Context()
        pub = ctx.socket(zmq.PUB)
        pub.setsockopt(zmq.SNDHWM, 2)
        pub.setsockopt(zmq.LINGER, 0)
        pub.bind(f"tcp://127.0.0.1:{cam_port}")
        img = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
        base = bytearray(encode_frame(img, bottom_up=True))
        row_off = 479 * 640 * 4  # wire row 479 = image row 0 after the bottom-up flip; B G R A of pixels 0, 1
        # the counter sits in image bytes 0..3 = B G R of pixel 0 and B of pixel 1: wire bytes 0,1,2 and 4
        proto = sample_frame()

        sent_udp: dict[int, float] = {}
        sent_cam: dict[int, float] = {}
        rtt: list[tuple[int, float]] = []
        stop_rx = threading.Event()

        def rx():
            sock.settimeout(0.1)
            while not stop_rx.is_set():
                try:
                    data, _ = sock.recvfrom(65536)
                except socket.timeout:
                    continue
                except OSError:  # e.g. an ICMP error while the bridge was not up yet
                    continue
                t = time.monotonic()
                try:
                    c = Command.decode(data)
                except ProtocolError:
                    continue
                t0 = sent_udp.get(c.seq)
                if t0 is not None:
                    rtt.append((c.seq, t - t0))
        th = threading.Thread(target=rx, daemon=True)
        th.start()

        def cam_bytes(counter):
            b = base
            v = int(counter).to_bytes(4, "little")
            b[row_off + 0], b[row_off + 1], b[row_off + 2], b[row_off + 4] = v[0], v[1], v[2], v[3]
            return bytes(b)

        # warm-up (until both subscribers have their first message: discovery, connections; then the camera
        # stamper's phase), then phase 1a (control path alone) and 1b (with the camera at --camera-fps,
        # published just before the cycle's SensorFrame as SimTwo does)
        seq, cam_counter = 0, 1
        period = 1.0 / args.rate
        cam_every = max(1, int(round(args.rate / args.camera_fps))) if args.camera_fps > 0 else 0
        phase_of: dict[int, str] = {}

        def send_cycle(phase: str | None, camera: bool):
            nonlocal seq, cam_counter
            if camera and cam_every and seq % cam_every == 0:
                data = cam_bytes(cam_counter)
                t = time.monotonic()
                pub.send(data, copy=False)
                if phase:
                    sent_cam[cam_counter] = t
                cam_counter += 1
            f = SensorFrame(seq=seq, time_ms=(seq + 1) * 40, enc_delta=(1, 1), enc_total=(seq + 1, seq + 1),
                            x=proto.x, y=proto.y, theta=proto.theta, contact=False, magnet=False, ranges=proto.ranges)
            data = f.encode()
            t = time.monotonic()
            if phase:
                sent_udp[seq] = t  # before sending: the reply may come back before sendto returns
                phase_of[seq] = phase
            sock.sendto(data, ("127.0.0.1", port))
            seq += 1

        def paced(seconds, phase, camera, until=None):
            t0 = time.monotonic()
            n = 0
            while time.monotonic() - t0 < seconds:
                send_cycle(phase, camera)
                n += 1
                if until is not None and n % 10 == 0:
                    procs.check()
                    if until():
                        return True
                wait = t0 + n * period - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            return False

        ready = [tmp / f"sub_{w}.json.ready" for w in ("odom", "image")]
        t_up = time.monotonic()
        if not paced(90.0, None, True, until=lambda: all(p.exists() for p in ready)):
            raise RuntimeError(f"the bridge or the bench subscribers did not come up in 90 s (logs in {tmp}): "
                               f"{procs.tail('bridge')}\n{procs.tail('sub_odom')}\n{procs.tail('sub_image')}")
        startup_s = time.monotonic() - t_up
        paced(2.0, None, True)
        rtt.clear()
        paced(args.seconds, "alone", False)
        paced(args.seconds, "camera", True)
        time.sleep(0.5)
        # phase 2: camera flood (SensorFrames keep flowing at 25 Hz for the stamper)
        flood_counter_start = cam_counter
        t0 = time.monotonic()
        next_udp = t0
        n_flood = 0
        while time.monotonic() - t0 < args.camera_seconds:
            data = cam_bytes(cam_counter)
            sent_cam[cam_counter] = time.monotonic()
            pub.send(data, copy=False)
            cam_counter += 1
            n_flood += 1
            if time.monotonic() >= next_udp:
                f = SensorFrame(seq=seq, time_ms=(seq + 1) * 40, enc_delta=(0, 0), enc_total=(seq, seq), x=0, y=0,
                                theta=0, contact=False, magnet=False, ranges=proto.ranges)
                sock.sendto(f.encode(), ("127.0.0.1", port))
                seq += 1
                next_udp += 0.04
            time.sleep(0.0005)
        flood_t1 = time.monotonic()
        time.sleep(1.0)
        stop_rx.set()
        th.join(1)
        res = {}
        for what in ("odom", "image"):
            procs.stop(f"sub_{what}")
            res.update({k: v for k, v in json.loads((tmp / f"sub_{what}.json").read_text()).items() if v})
        sock.close()
        pub.close(0)
        ctx.term()
    finally:
        procs.stop_all()
        graph.cleanup()
    import shutil

    shutil.rmtree(tmp, ignore_errors=True)  # the processes' logs: kept only when the run failed

    # --- analysis ---
    odom_lat = {"alone": [], "camera": []}
    for st, t in res.get("odom", []):
        sq = st // 40_000_000 - 1
        if sq in sent_udp:
            odom_lat[phase_of[sq]].append(t - sent_udp[sq])
    rtt_by = {"alone": [rt for sq, rt in rtt if phase_of.get(sq) == "alone"],
              "camera": [rt for sq, rt in rtt if phase_of.get(sq) == "camera"]}
    lat_cam = [t - sent_cam[c] for c, t, _ in res.get("images", []) if c in sent_cam and c < flood_counter_start]
    n_cam_sent = sum(1 for c in sent_cam if c < flood_counter_start)
    flood_in = [t for c, t, _ in res.get("images", []) if c >= flood_counter_start and t0 + 0.5 <= t <= flood_t1]
    cam_fps = (len(flood_in) - 1) / (flood_in[-1] - flood_in[0]) if len(flood_in) > 2 else 0.0
    n_sent_alone = sum(1 for p in phase_of.values() if p == "alone")

    def ms(xs, q):
        return float(np.percentile(np.array(xs) * 1000, q)) if xs else float("nan")

    p99 = ms(odom_lat["alone"], 99)
    return {
        "middleware": middleware(),
        "bridge_args": args.bridge_args or "(none)",
        "graph_startup_s": startup_s,
        "sensor_frames_per_s": args.rate,
        "reply_rtt_median_ms": ms(rtt_by["alone"], 50),
        "reply_rtt_p99_ms": ms(rtt_by["alone"], 99),
        "odom_latency_median_ms": ms(odom_lat["alone"], 50),
        "odom_latency_p99_ms": p99,
        "odom_latency_max_ms": ms(odom_lat["alone"], 100),
        "odom_samples": len(odom_lat["alone"]),
        "odom_lost": n_sent_alone - len(odom_lat["alone"]),
        "reply_rtt_p99_with_camera_ms": ms(rtt_by["camera"], 99),
        "odom_latency_median_with_camera_ms": ms(odom_lat["camera"], 50),
        "odom_latency_p99_with_camera_ms": ms(odom_lat["camera"], 99),
        "camera_frames_per_s_with_control": args.camera_fps,
        "camera_latency_median_ms": ms(lat_cam, 50),
        "camera_latency_p99_ms": ms(lat_cam, 99),
        "camera_frames_measured": len(lat_cam),
        "camera_frames_lost_with_control": n_cam_sent - len(lat_cam),
        "camera_sent_in_flood_frames_per_s": n_flood / (flood_t1 - t0),
        "camera_max_frames_per_s": cam_fps,
        "odom_p99_target_met": bool(odom_lat["alone"]) and p99 <= 2.0,
        "camera_rate_target_met": cam_fps >= 100.0,
    }


def main(argv: list[str] | None = None) -> int:
    """``python -m robotatfactory.bench.bridge --out FILE [options]``: one :func:`measure` on this
    interpreter's middleware (what :func:`measure_in` runs), its figures written to FILE as JSON."""
    import argparse

    from ..results import flat, write_json

    p = argparse.ArgumentParser(prog="python -m robotatfactory.bench.bridge")
    p.add_argument("--out", required=True)
    add_arguments(p)
    args = p.parse_args(argv)
    write_json(args.out, flat(measure(args)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
