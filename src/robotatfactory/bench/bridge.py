"""``raf bench bridge``: latency and throughput of the ROS bridge, with real processes.

A dedicated sender (this process, no physics) plays the simulator: SensorFrames over UDP and camera frames
over ZMQ; a private roscore (free port), the real bridge node (``raf bridge``, its own process) and two
subscriber processes (``bench/_bridge_sub.py``, ``tcp_nodelay``): one for odom (a controller), one for
images (a vision node). All processes read the same system-wide monotonic clock, so a datagram's send time and the subscriber's receive time compare directly.

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
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

NAME = "bridge"
HELP = "bridge latency (datagram -> Command reply, datagram -> odom subscriber, camera -> image subscriber) and camera throughput"
TARGETS = {
    "odom_latency_p99_ms": "<= 2 ms (issue 4: control path p99)",
    "camera_max_frames_per_s": ">= 100 frames/s sustained (issue 4)",
}


def add_arguments(parser) -> None:
    parser.add_argument("--rate", type=float, default=100.0, help="SensorFrames per second in phase 1 (default 100)")
    parser.add_argument("--seconds", type=float, default=10.0, help="length of phases 1a and 1b (default 10 s each)")
    parser.add_argument("--camera-seconds", type=float, default=5.0, help="length of phase 2 (default 5 s)")
    parser.add_argument("--camera-fps", type=float, default=15.0, help="camera rate in phase 1b (default 15)")


def run(args) -> dict:
    import zmq

    from ..ros.master import PrivateMaster, free_port, stop_process
    from ..simtwo import Command, ProtocolError, SensorFrame, encode_frame
    from .protocol import sample_frame

    tmp = Path(tempfile.mkdtemp(prefix="raf-bench-bridge-"))
    master = PrivateMaster().start()
    env = master.env()
    port = free_port(socket.SOCK_DGRAM)
    cam_port = free_port()
    procs = []
    try:
        bridge = subprocess.Popen([sys.executable, "-m", "robotatfactory", "bridge", "--port", str(port), "--camera",
                                   f"tcp://127.0.0.1:{cam_port}", "--set", "watchdog/timeout=1000"],
                                  env=env, stdout=open(tmp / "bridge.log", "wb"), stderr=subprocess.STDOUT,
                                  start_new_session=True)
        procs.append(bridge)
        subs = {}
        for what in ("odom", "image"):
            subs[what] = subprocess.Popen([sys.executable, "-m", "robotatfactory.bench._bridge_sub",
                                           str(tmp / f"sub_{what}.json"), what], env=env,
                                          stdout=open(tmp / f"sub_{what}.log", "wb"), stderr=subprocess.STDOUT,
                                          start_new_session=True)
            procs.append(subs[what])
        _wait_for_subscriber(env, timeout=30)

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

        # warm-up (connections, the camera stamper's phase), then phase 1a (control path alone) and 1b (with
        # the camera at --camera-fps, published just before the cycle's SensorFrame as SimTwo does)
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

        def paced(seconds, phase, camera):
            t0 = time.monotonic()
            n = 0
            while time.monotonic() - t0 < seconds:
                send_cycle(phase, camera)
                n += 1
                wait = t0 + n * period - time.monotonic()
                if wait > 0:
                    time.sleep(wait)

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
        for what, sub in subs.items():
            stop_process(sub)
            res.update({k: v for k, v in json.loads((tmp / f"sub_{what}.json").read_text()).items() if v})
        sock.close()
        pub.close(0)
        ctx.term()
    finally:
        for p in procs:
            stop_process(p)
        master.cleanup()

    # --- analysis ---
    odom_lat = {"alone": [], "camera": []}
    for st, t in res.get("odom", []):
        sq = st // 40_000_000 - 1
        if sq in sent_udp:
            odom_lat[phase_of[sq]].append(t - sent_udp[sq])
    rtt_by = {"alone": [rt for sq, rt in rtt if phase_of.get(sq) == "alone"],
              "camera": [rt for sq, rt in rtt if phase_of.get(sq) == "camera"]}
    lat_cam = [t - sent_cam[c] for c, t, _ in res.get("images", []) if c in sent_cam and c < flood_counter_start]
    flood_in = [t for c, t, _ in res.get("images", []) if c >= flood_counter_start and t0 + 0.5 <= t <= flood_t1]
    cam_fps = (len(flood_in) - 1) / (flood_in[-1] - flood_in[0]) if len(flood_in) > 2 else 0.0

    def ms(xs, q):
        return float(np.percentile(np.array(xs) * 1000, q)) if xs else float("nan")

    p99 = ms(odom_lat["alone"], 99)
    return {
        "sensor_frames_per_s": args.rate,
        "reply_rtt_median_ms": ms(rtt_by["alone"], 50),
        "reply_rtt_p99_ms": ms(rtt_by["alone"], 99),
        "odom_latency_median_ms": ms(odom_lat["alone"], 50),
        "odom_latency_p99_ms": p99,
        "odom_latency_max_ms": ms(odom_lat["alone"], 100),
        "odom_samples": len(odom_lat["alone"]),
        "reply_rtt_p99_with_camera_ms": ms(rtt_by["camera"], 99),
        "odom_latency_median_with_camera_ms": ms(odom_lat["camera"], 50),
        "odom_latency_p99_with_camera_ms": ms(odom_lat["camera"], 99),
        "camera_frames_per_s_with_control": args.camera_fps,
        "camera_latency_median_ms": ms(lat_cam, 50),
        "camera_latency_p99_ms": ms(lat_cam, 99),
        "camera_frames_measured": len(lat_cam),
        "camera_sent_in_flood_frames_per_s": n_flood / (flood_t1 - t0),
        "camera_max_frames_per_s": cam_fps,
        "odom_p99_target_met": bool(odom_lat["alone"]) and p99 <= 2.0,
        "camera_rate_target_met": cam_fps >= 100.0,
    }


def _wait_for_subscriber(env: dict, timeout: float) -> None:
    import xmlrpc.client

    master = xmlrpc.client.ServerProxy(env["ROS_MASTER_URI"])
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            code, _, state = master.getSystemState("/raf_bench")
            subs = {t: n for t, n in state[1]}
            pubs = {t: n for t, n in state[0]}
            if "/odom" in subs and "/odom" in pubs and "/camera/image_raw" in subs and "/camera/image_raw" in pubs:
                time.sleep(0.5)
                return
        except OSError:
            pass
        time.sleep(0.1)
    raise RuntimeError("the bridge or the bench subscriber did not come up")
