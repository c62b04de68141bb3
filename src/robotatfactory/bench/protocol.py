"""``raf bench protocol``: encode/decode rates of a full SensorFrame (360 LIDAR rays), a Command and a camera frame."""
from __future__ import annotations

import time

import numpy as np

NAME = "protocol"
HELP = "decode and encode rates of a full sensor frame (360 rays), a command and a camera frame, on one core"
TARGETS = {"sensor_frame_decode_frames_per_s": ">= 20,000 (issue 2)"}


def add_arguments(parser) -> None:
    parser.add_argument("--seconds", type=float, default=1.0, help="time per measured loop (default 1.0)")
    parser.add_argument("--repeats", type=int, default=5, help="loops per figure; the median is reported")


def _rate(fn, seconds: float, repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        n, t0 = 0, time.perf_counter()
        while True:
            for _ in range(50):
                fn()
            n += 50
            dt = time.perf_counter() - t0
            if dt >= seconds:
                break
        rates.append(n / dt)
    return float(np.median(rates))


def sample_frame(seed: int = 0):
    from ..simtwo import SensorFrame

    rng = np.random.default_rng(seed)
    ranges = np.array([float("%.6g" % r) for r in rng.uniform(0.05, 6.0, 360)])
    ranges[rng.random(360) < 0.1] = -1.0
    return SensorFrame(seq=123456, time_ms=4_938_120, enc_delta=(17, -16), enc_total=(123_456, -98_765),
                       x=-0.725123, y=0.401235, theta=1.5708, contact=False, magnet=True, ranges=ranges)


def run(args) -> dict:
    from ..simtwo import Command, SensorFrame, decode_frame, encode_frame

    frame = sample_frame()
    data = frame.encode()
    assert SensorFrame.decode(data) == frame
    cmd = Command(0.2991, -1.25e-5, True, 123456).encode()
    img = np.random.default_rng(1).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    raw = encode_frame(img)
    s, r = args.seconds, args.repeats
    return {
        "sensor_frame_bytes": len(data),
        "sensor_frame_rays": len(frame.ranges),
        "sensor_frame_decode_frames_per_s": _rate(lambda: SensorFrame.decode(data), s, r),
        "sensor_frame_encode_frames_per_s": _rate(frame.encode, s, r),
        "command_decode_per_s": _rate(lambda: Command.decode(cmd), s, r),
        "camera_decode_frames_per_s": _rate(lambda: decode_frame(raw), s, r),
    }
