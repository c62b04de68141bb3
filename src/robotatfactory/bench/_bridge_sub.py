"""Subscriber process of ``raf bench bridge``: records when odom and camera frames arrive (monotonic clock).

Run as ``python -m robotatfactory.bench._bridge_sub OUT.json [odom,image]`` on either middleware (:mod:`..ros.mw`,
``RAF_MIDDLEWARE``); writes ``OUT.json`` on SIGINT, and ``OUT.json.ready`` once the first message of each kind
it listens to has arrived (the bench's sign that discovery and connections are done). The bench runs one for
odom (a controller) and one for images (a vision node), as a real system would. QoS: odom reliable, images
best effort (what the bridge publishes them with on ROS 2).
"""
from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path


def main(out: str, what: str = "odom,image") -> None:
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image

    from ..ros.messages import diagnostic_values
    from ..ros.mw import QoS, api
    from ..ros.mw.base import stamp_ns

    mw = api()
    node = mw.init_node("raf_bench_sub", argv=[sys.argv[0]], anonymous=True)
    lock = threading.Lock()
    odom: list = []
    images: list = []
    wanted = {w for w in ("odom", "image") if w in what}
    seen: set = set()

    def first(kind):
        with lock:
            if kind in seen:
                return
            seen.add(kind)
            done = wanted <= seen
        if done:
            Path(out + ".ready").write_text("ready\n")

    def on_odom(m):
        t = time.monotonic()
        with lock:
            odom.append((stamp_ns(m.header.stamp), t))
        if "odom" not in seen:
            first("odom")

    def on_image(m):
        t = time.monotonic()
        counter = int.from_bytes(bytes(m.data[:4]), "little")
        with lock:
            images.append((counter, t, stamp_ns(m.header.stamp)))
        if "image" not in seen:
            first("image")

    diag = {}

    def on_diag(m):
        for st in m.status:
            if st.name.endswith("sensor stream"):
                diag.update(diagnostic_values(st))

    if "odom" in wanted:
        from diagnostic_msgs.msg import DiagnosticArray

        node.subscribe("odom", Odometry, on_odom, QoS.SYNCHRONOUS, 100)
        node.subscribe("/diagnostics", DiagnosticArray, on_diag, QoS.RELIABLE, 10)
    if "image" in wanted:
        node.subscribe("camera/image_raw", Image, on_image, QoS.SENSOR, 100, large=True)
    # ROS 2: one thread, as rclpy.spin(node) has it: what a Python controller or vision node runs with (rospy
    # serves each subscription from a thread of its own)
    node.set_executor("single")
    try:
        node.spin()
    finally:
        with lock:
            with open(out, "w") as fh:
                json.dump({"odom": odom, "images": images, "diag": diag}, fh)
        node.finish()


if __name__ == "__main__":
    main(*sys.argv[1:])
