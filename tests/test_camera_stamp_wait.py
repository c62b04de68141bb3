"""The camera node's wait for an overdue SensorFrame (the elapsed rule, the bridge's default) when the bridge
passes the SensorFrames' timing on late (a loaded bridge process): a frame is never stamped from a SensorFrame
history known to be incomplete because a newer frame arrived meanwhile; the newest frame waits, within the
first frame's bound, and is stamped after the SensorFrames that came before it."""
import socket
import threading
import time
from types import SimpleNamespace

from robotatfactory.ros.camera_node import TIMING, CameraBridge

P = 40  # ms


def _cfg():
    from robotatfactory.ros.config import load_config

    return load_config({"camera": {"latency": 0.0}})


def test_a_newer_frame_does_not_cut_short_the_wait_for_the_bridges_late_sensor_frames():
    bridge_end, camera_end = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    node = SimpleNamespace(warn=print, error=print, ok=lambda: True, name="/raf_bridge_camera")
    cam = CameraBridge(_cfg(), node, timing_sock=camera_end)
    cam._size_ok = lambda buf: True
    stamped = []
    cam.publish_frame = lambda buf, stamp_s, arrival=None: stamped.append((buf, stamp_s))
    base = time.monotonic()
    for i in range(1, 11):  # SensorFrames Tms 40..400, the last one arrived at base, passed on in time
        bridge_end.send(TIMING.pack(P * i, base + 0.04 * (i - 10), -1))
    cam._running = True
    pub = threading.Thread(target=cam._publish, daemon=True)
    pub.start()

    def frame(name: str, arrival: float) -> None:
        time.sleep(max(0.0, arrival - time.monotonic()))
        with cam._cv:
            skipped = 0
            if cam._mail is not None:
                skipped = 1 + cam._mail[2]
            cam._mail = (arrival, SimpleNamespace(buffer=name), skipped)
            cam._cv.notify()
        with cam._timing_cv:
            cam._timing_cv.notify_all()

    try:
        # the bridge stalls: the SensorFrames Tms 440..600 arrive every 40 ms but reach the camera node only
        # 0.3 s after base. Frame A arrives 0.15 s after the last SensorFrame known (rendered ~550 ms), frame B
        # at 0.19 s (~590 ms)
        frame("A", base + 0.15)
        frame("B", base + 0.19)
        time.sleep(max(0.0, base + 0.3 - time.monotonic()))
        for i in range(11, 16):
            bridge_end.send(TIMING.pack(P * i, base + 0.04 * (i - 10), -1))
        end = time.monotonic() + 2
        while not stamped and time.monotonic() < end:
            time.sleep(0.01)
    finally:
        cam._running = False
        with cam._cv:
            cam._cv.notify_all()
        pub.join(2)
    assert stamped, "nothing published"
    # B: after Tms 560 (arrived base + 0.16) by 30 ms; never A stamped from Tms 400 (at most 440: 110 ms early)
    assert [b for b, _ in stamped] == ["B"], stamped
    assert abs(stamped[0][1] - 0.590) < 0.002, stamped
    assert cam.counts["skipped"] >= 1
