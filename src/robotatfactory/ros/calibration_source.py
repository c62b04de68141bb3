"""Camera images and odometry for ``raf calibrate``: read from a rosbag or recorded live (thin ROS wiring).

Both hand every kept image to ``sink(stamp_s, BGR uint8 array)`` as it is read (so a long recording is never
held in memory: the command detects the markers there and keeps only the corners) and return
``(images_kept, odometry)`` with odometry as a list of ``(stamp_s, x, y, theta)`` (``base_link`` in ``odom``),
oldest first. Everything else (detection, interpolation, the fit) is plain Python in
:mod:`robotatfactory.localization.calibration` and the command.
"""
from __future__ import annotations

import math
import time

import numpy as np

from ..errors import ConfigError
from .mw.base import stamp_s


def image_to_bgr(msg) -> np.ndarray:
    """A sensor_msgs/Image as a BGR (or grey) array (:func:`ros.messages.image_to_bgr`); a bad image is a
    ConfigError naming it."""
    from .messages import image_to_bgr as convert

    try:
        return convert(msg)
    except ValueError as e:
        raise ConfigError(f"camera image: {e} (bgr8, rgb8, bgra8, rgba8, mono8 are read)") from None


def odom_pose(msg) -> tuple[float, float, float, float]:
    """(stamp s, x, y, theta) of a nav_msgs/Odometry of either ROS generation (or a bag's copy of one)."""
    from .messages import quaternion_yaw

    p = msg.pose.pose
    return (stamp_s(msg.header.stamp), p.position.x, p.position.y, quaternion_yaw(p.orientation))


def read_bag(path: str, image_topic: str, odom_topic: str | None, sink, every: int = 1, max_images: int = 0):
    """Images (every ``every``-th, at most ``max_images`` if > 0) to ``sink`` and odometry from a bag: a ROS 1
    ``.bag``, a rosbag2 directory or a ``.mcap``/``.db3`` file (:mod:`.bags`, either middleware or none)."""
    from .bags import find_topic, open_bag

    with open_bag(path) as bag:
        topics = bag.topics
        img_topics = find_topic(topics, image_topic)
        if not img_topics:
            listing = ", ".join(f"{t} ({v.msgtype}, {v.count})" for t, v in sorted(topics.items())) or "none"
            raise ConfigError(f"bag {path} has no image topic {image_topic!r} (--image-topic); its topics: {listing}")
        if len(img_topics) > 1:
            raise ConfigError(f"bag {path}: several topics match {image_topic!r}: {img_topics}; name one exactly")
        if topics[img_topics[0]].msgtype != "sensor_msgs/msg/Image":
            raise ConfigError(f"bag {path}: {img_topics[0]} holds {topics[img_topics[0]].msgtype}, not sensor_msgs/Image")
        od_topics = [t for t in (find_topic(topics, odom_topic) if odom_topic else [])
                     if topics[t].msgtype == "nav_msgs/msg/Odometry"]
        wanted = img_topics + od_topics[:1]
        odom = []
        k = kept = 0
        for topic, t_ns, msg in bag.messages(wanted):
            if topic == img_topics[0]:
                if k % max(1, every) == 0 and (max_images <= 0 or kept < max_images):
                    sink(stamp_s(msg.header.stamp) or t_ns * 1e-9, image_to_bgr(msg))
                    kept += 1
                k += 1
            else:
                odom.append(odom_pose(msg))
    if not kept:
        raise ConfigError(f"bag {path}: no images on {img_topics[0]}")
    odom.sort(key=lambda a: a[0])
    return kept, odom


def record_live(image_topic: str, odom_topic: str | None, duration: float, sink, every: int = 1,
                max_images: int = 0):
    """Subscribe for ``duration`` wall seconds on this process's middleware (:mod:`.mw`; ROS 1 needs a
    master, ROS 2 finds the publishers in its domain); images to ``sink`` (one at a time), odometry
    returned. Images are sensor data (ROS 2: best effort, matching the bridge's camera), odometry reliable."""
    import sys
    import threading

    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image

    from .mw import QoS, api

    if not duration > 0 or not math.isfinite(duration):
        raise ConfigError(f"--duration must be a positive number of seconds, got {duration!r}")
    m = api()
    m.require_master("start roscore and the bridge first")  # ROS 1; ROS 2 has no master
    node = m.init_node("raf_calibrate", argv=[sys.argv[0]], anonymous=True, signals=False)
    lock = threading.Lock()
    done = threading.Event()
    odom, count, kept, bad = [], [0], [0], [0]

    def on_image(msg):
        with lock:
            if done.is_set():
                return
            k = count[0]
            count[0] += 1
            if k % max(1, every) or (max_images > 0 and kept[0] >= max_images):
                return
            try:
                img = image_to_bgr(msg)
            except ConfigError:
                bad[0] += 1
                return
            sink(stamp_s(msg.header.stamp), img)
            kept[0] += 1

    def on_odom(msg):
        with lock:
            if not done.is_set():
                odom.append(odom_pose(msg))

    topic = node.resolve(image_topic)
    subs = [node.subscribe(image_topic, Image, on_image, QoS.SENSOR, 10, large=True)]
    if odom_topic:
        subs.append(node.subscribe(odom_topic, Odometry, on_odom, QoS.RELIABLE, 200))
    spinner = threading.Thread(target=node.spin, name="raf-calibrate-spin", daemon=True)
    spinner.start()
    try:
        t_end = time.monotonic() + duration
        while time.monotonic() < t_end and node.ok():
            time.sleep(0.1)
    finally:
        done.set()
        for s in subs:
            node.close(s)
        node.finish("raf calibrate: recording done", spinner)
    with lock:
        if not kept[0]:
            extra = f" ({bad[0]} in an unsupported encoding)" if bad[0] else ""
            raise ConfigError(f"no images arrived on {topic} in {duration:g} s{extra} "
                              f"(is the bridge running and the robot's camera on?)")
        return kept[0], sorted(odom, key=lambda a: a[0])
