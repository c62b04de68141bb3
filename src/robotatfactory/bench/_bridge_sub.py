"""Subscriber process of ``raf bench bridge``: records when odom and camera frames arrive (monotonic clock).

Run as ``python -m robotatfactory.bench._bridge_sub OUT.json [odom,image]``; writes ``OUT.json`` on SIGINT.
The bench runs one for odom (a controller) and one for images (a vision node), as a real system would.
"""
from __future__ import annotations

import json
import sys
import threading
import time


def main(out: str, what: str = "odom,image") -> None:
    import rospy
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image

    rospy.init_node("raf_bench_sub", anonymous=True)
    lock = threading.Lock()
    odom: list = []
    images: list = []

    def on_odom(m):
        t = time.monotonic()
        with lock:
            odom.append((m.header.stamp.to_nsec(), t))

    def on_image(m):
        t = time.monotonic()
        counter = int.from_bytes(bytes(m.data[:4]), "little")
        with lock:
            images.append((counter, t, m.header.stamp.to_nsec()))

    diag = {}

    def on_diag(m):
        for st in m.status:
            if st.name.endswith("sensor stream"):
                diag.update({kv.key: kv.value for kv in st.values})

    if "odom" in what:
        from diagnostic_msgs.msg import DiagnosticArray

        rospy.Subscriber("odom", Odometry, on_odom, queue_size=100, tcp_nodelay=True)
        rospy.Subscriber("/diagnostics", DiagnosticArray, on_diag, queue_size=10)
    if "image" in what:
        rospy.Subscriber("camera/image_raw", Image, on_image, queue_size=100, tcp_nodelay=True, buff_size=1 << 24)
    rospy.spin()
    with lock:
        with open(out, "w") as fh:
            json.dump({"odom": odom, "images": images, "diag": diag}, fh)


if __name__ == "__main__":
    main(*sys.argv[1:])
