"""The camera node notices a restarted camera publisher (frames carry no sequence number) by ZMQ's connection
events: it counts the restart and re-synchronises the stamper's frame counting, keeping the SensorFrames."""
import threading
import time
from types import SimpleNamespace

import zmq

from robotatfactory.ros.camera_node import CameraBridge
from rosutil import free_port, wait_until


def _cfg(endpoint: str):
    from robotatfactory.ros.config import load_config

    return load_config({"camera": {"endpoint": endpoint}})


def _publish_until(pub, cam, received: int, timeout: float = 10.0) -> None:
    end = time.monotonic() + timeout
    while cam.counts["received"] < received and time.monotonic() < end:
        pub.send(b"\0" * 16)
        time.sleep(0.02)
    assert cam.counts["received"] >= received, cam.counts


def test_a_restarted_publisher_is_counted_and_resynchronises_the_stamper():
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    logged = []
    node = SimpleNamespace(warn=logged.append, error=logged.append, ok=lambda: True, name="/raf_bridge_camera")
    cam = CameraBridge(_cfg(endpoint), node)
    cam.stamper.on_sensor_frame(40, time.monotonic())
    resyncs = []
    original = cam.stamper.resync_frames
    cam.stamper.resync_frames = lambda: (resyncs.append(1), original())
    cam._running = True
    rx = threading.Thread(target=cam._rx, daemon=True)
    ctx = zmq.Context.instance()
    pub = ctx.socket(zmq.PUB)
    pub.setsockopt(zmq.LINGER, 0)
    pub.bind(endpoint)
    rx.start()
    try:
        _publish_until(pub, cam, 3)
        assert cam.counts["publisher_restarts"] == 0  # the first connection is no restart
        pub.close(0)
        time.sleep(0.3)
        pub = ctx.socket(zmq.PUB)
        pub.setsockopt(zmq.LINGER, 0)
        pub.bind(endpoint)
        n = cam.counts["received"]
        _publish_until(pub, cam, n + 3)
        wait_until(lambda: cam.counts["publisher_restarts"] == 1, 5, what="the restart counted")
        assert resyncs == [1]
        assert any("restarted" in line for line in logged), logged
        assert len(cam.stamper._tms) == 1  # the SensorFrames are kept
    finally:
        cam._running = False
        rx.join(2.0)
        pub.close(0)
    assert not rx.is_alive()
