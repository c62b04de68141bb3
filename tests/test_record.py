"""``raf record`` and :mod:`robotatfactory.ros.bags` on the middleware this interpreter has: a short run of
``raf up`` recorded and read back (counts, stamps increasing, an Odometry's fields, the field's static TFs);
on ROS 2 the bag's metadata carries Jazzy's type hashes, the same the live graph announces; on ROS 1 Debian's
rosbag reads the bag. Unit tests: message objects round-trip through a bag; an image comes back as pixels."""
from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from robotatfactory.errors import ConfigError
from robotatfactory.ros import bags, mw
from robotatfactory.ros.master import private_graph, stop_process
from robotatfactory.ros.mw.base import stamp_ns

ROOT = Path(__file__).resolve().parents[1]
FORMATS = {"ros1": ["bag"], "ros2": ["mcap", "sqlite3"]}
pytestmark = pytest.mark.middlewares  # conftest's `middleware`: ros1 in .venv, ros2 in .venv-ros2
# real ROS 2 Jazzy's tf2_msgs/msg/TFMessage (scripts/check_ros2.py checks the venv's build against it)
TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"


def _time_msg(ns: int):
    return mw.api().time_msg(ns)


# ---- unit: the writer and the reader ---------------------------------------------------------------------

def test_messages_round_trip_through_a_bag(tmp_path, middleware):
    for fmt in FORMATS[middleware]:
        _round_trip(tmp_path, fmt)


def _round_trip(tmp_path, fmt):
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Image

    path = tmp_path / ("b.bag" if fmt == "bag" else f"b_{fmt}")
    img = np.random.default_rng(1).integers(0, 255, (48, 64, 3), dtype=np.uint8)
    with bags.open_writer(path, fmt) as w:
        for k in range(5):
            o = Odometry()
            o.header.stamp = _time_msg(40_000_000 * k)
            o.header.frame_id, o.child_frame_id = "odom", "base_link"
            o.pose.pose.position.x = 0.1 * k
            o.pose.pose.orientation.w = 1.0
            w.write("/odom", o, 40_000_000 * k)
        m = Image(height=48, width=64, encoding="bgr8", step=64 * 3, data=img.tobytes())
        m.header.stamp = _time_msg(123_000_000)
        w.write("/camera/image_raw", m, 123_000_000)
    with bags.open_bag(path) as b:
        assert b.topics == {"/odom": bags.TopicInfo("nav_msgs/msg/Odometry", 5),
                            "/camera/image_raw": bags.TopicInfo("sensor_msgs/msg/Image", 1)}
        got = list(b.messages(["/odom"]))
        assert [t for _, t, _ in got] == [40_000_000 * k for k in range(5)]
        assert [round(m.pose.pose.position.x, 9) for *_, m in got] == [0.0, 0.1, 0.2, 0.3, 0.4]
        assert got[2][2].child_frame_id == "base_link" and stamp_ns(got[2][2].header.stamp) == 80_000_000
        (_, t, im), = b.messages(["/camera/image_raw"])
    from robotatfactory.ros.calibration_source import image_to_bgr

    assert np.array_equal(image_to_bgr(im), img)


def test_a_bag_is_never_overwritten_and_bad_paths_say_so(tmp_path, middleware):
    p = tmp_path / ("x.bag" if middleware == "ros1" else "x")
    bags.open_writer(p).close()
    with pytest.raises(ConfigError, match="exists already"):
        bags.open_writer(p)
    with pytest.raises(ConfigError, match="no such file"):
        bags.open_bag(tmp_path / "missing.bag")
    with pytest.raises(ConfigError, match="format"):
        bags.BagWriter(tmp_path / "y", "zip")


def test_type_names(middleware):
    assert bags.normalize_type("nav_msgs/Odometry") == "nav_msgs/msg/Odometry"
    assert bags.normalize_type("/nav_msgs/msg/Odometry") == "nav_msgs/msg/Odometry"
    from nav_msgs.msg import Odometry

    assert bags.msgtype_of(Odometry()) == "nav_msgs/msg/Odometry"
    topics = {"/robot1/camera/image_raw": None, "/camera/camera_info": None}
    assert bags.find_topic(topics, "camera/image_raw") == ["/robot1/camera/image_raw"]


class _ClockNode:
    """A node whose sim clock is invalid (0) until ``tick``; one latched publisher on /tf_static."""

    def __init__(self):
        self.ns, self.subscribed, self.said = 0, [], []

    def resolve(self, t):
        return t if t.startswith("/") else "/" + t

    def now(self):
        return _time_msg(self.ns)

    def topic_types(self):
        return {"/tf_static": "tf2_msgs/msg/TFMessage", "/odom": "nav_msgs/msg/Odometry"}

    def subscribe_raw(self, topic, msgtype, cb):
        self.subscribed.append(topic)
        cb(b"latched", None) if topic == "/tf_static" else None  # a latched message comes at once
        return object(), None

    def info(self, text, throttle=0.0):
        self.said.append(text)

    warn = info

    def close(self, sub):
        pass


class _Writer:
    def __init__(self):
        self.times, self.topics = [], set()

    def has_topic(self, t):
        return True

    def write_raw(self, topic, data, t):
        self.times.append((topic, t))

    def close(self):
        pass


def test_on_simulation_time_recording_starts_at_the_first_clock(middleware):
    from robotatfactory.ros.recorder import Recorder

    node, writer = _ClockNode(), _Writer()
    rec = Recorder(node, writer, ["/tf_static", "odom"], rescan=0.05).start()
    try:
        time.sleep(0.3)
        assert node.subscribed == [] and not rec.recording.is_set(), node.subscribed
        assert sum("waiting for the first /clock" in s for s in node.said) == 1, node.said
        node.ns = 12_500_000_000  # the first /clock
        assert rec.recording.wait(2.0)
        end = time.monotonic() + 2
        while time.monotonic() < end and len(node.subscribed) < 2:
            time.sleep(0.02)
    finally:
        rec.stop()
    assert sorted(node.subscribed) == ["/odom", "/tf_static"]
    assert writer.times == [("/tf_static", 12_500_000_000)], "the latched message at a valid time, never 0"
    # wall time: no clock needed
    node2 = _ClockNode()
    rec2 = Recorder(node2, _Writer(), ["/odom"], wall_time=True).start()
    rec2.stop()
    assert rec2.recording.is_set() and node2.subscribed == ["/odom"]


# ---- a recorded run ---------------------------------------------------------------------------------

HASHES = textwrap.dedent("""
    import json, sys, time
    import rclpy
    from rclpy.node import Node
    rclpy.init()
    n = Node("raf_test_hashes")
    want, out = sys.argv[1:], {}
    end = time.monotonic() + 20
    while time.monotonic() < end and len(out) < len(want):
        for t in want:
            infos = n.get_publishers_info_by_topic(t)
            if infos:
                out[t] = str(infos[0].topic_type_hash)
        time.sleep(0.2)
    print(json.dumps(out))
    n.destroy_node()
    rclpy.try_shutdown()
""")


@pytest.mark.ros
@pytest.mark.slow
def test_record_a_run_and_read_it_back(tmp_path, middleware):
    graph = private_graph(middleware)
    graph.start()
    env = graph.env()
    out = tmp_path / ("run.bag" if middleware == "ros1" else "run")
    up = subprocess.Popen([sys.executable, "-m", "robotatfactory", "up", "--free-ports", "--no-localize",
                           "--log-dir", str(tmp_path / "logs")], env=env, cwd=ROOT, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, start_new_session=True)
    live_hashes = {}
    try:
        lines = []
        end = time.monotonic() + 120
        while time.monotonic() < end:
            line = up.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "raf up: running" in line:
                break
        assert "raf up: running" in "".join(lines), "".join(lines)
        rec = subprocess.run([sys.executable, "-m", "robotatfactory", "record", "-o", str(out), "--duration", "5",
                              "--topics", "odom", "/tf", "/tf_static", "scan", "camera/camera_info", "/clock"],
                             env=env, cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert rec.returncode == 0, rec.stdout[-2000:] + rec.stderr[-3000:]
        if middleware == "ros2":
            h = subprocess.run([sys.executable, "-c", HASHES, "/odom", "/tf", "/scan"], env=env, cwd=ROOT,
                               capture_output=True, text=True, timeout=60)
            assert h.returncode == 0, h.stderr[-2000:]
            live_hashes = json.loads(h.stdout.strip().splitlines()[-1])
        os.killpg(up.pid, signal.SIGINT)
        up.communicate(timeout=30)
    finally:
        stop_process(up, signal.SIGKILL)
        graph.cleanup()
    assert "wrote" in rec.stdout and "/odom" in rec.stdout, rec.stdout

    with bags.open_bag(out) as b:
        topics = b.topics
        assert b.format == ("rosbag1" if middleware == "ros1" else "rosbag2")
        assert topics["/odom"].msgtype == "nav_msgs/msg/Odometry" and topics["/odom"].count >= 30, topics
        assert topics["/tf"].count >= 30 and topics["/tf_static"].count >= 1, topics
        assert topics["/clock"].count >= 30 and topics["/scan"].count >= 5, topics
        odom = list(b.messages(["/odom"]))
        static = [m for _, _, m in b.messages(["/tf_static"])]
        infos = [m for _, _, m in b.messages(["/camera/camera_info"])]
    bag_times = [t for _, t, _ in odom]
    stamps = [stamp_ns(m.header.stamp) for _, _, m in odom]
    assert all(a <= c for a, c in zip(bag_times, bag_times[1:])), "bag time never goes back"
    assert all(a < c for a, c in zip(stamps, stamps[1:])), "odometry stamps increase"
    span = (stamps[-1] - stamps[0]) * 1e-9
    assert 1.0 < span < 5 * 3, f"{span} s of simulation time in 5 s of recording"
    # one Odometry per 40 ms control cycle, none lost between the first and the last recorded
    assert len(stamps) >= 0.95 * (span / 0.04 + 1), (len(stamps), span)
    # bag time is simulation time (the bridge's /clock), near the header's: the recording starts at the
    # recorder's first /clock, so nothing has the invalid time 0
    late = [(t, s) for t, s in zip(bag_times, stamps) if abs(t - s) >= 0.5e9]
    assert not late, late[:10]
    m = odom[-1][2]
    assert m.header.frame_id == "odom" and m.child_frame_id == "base_link"
    q = m.pose.pose.orientation
    assert math.isclose(q.x ** 2 + q.y ** 2 + q.z ** 2 + q.w ** 2, 1.0, abs_tol=1e-6)
    assert len(m.pose.covariance) == 36 and m.pose.covariance[0] >= 0
    children = {t.child_frame_id for t in static[-1].transforms}
    assert any(c.startswith("aruco_") for c in children), children
    assert infos and infos[0].width == 640 and infos[0].height == 480

    if middleware == "ros2":
        import yaml

        meta = yaml.safe_load((out / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
        assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
        assert (out / meta["relative_file_paths"][0]).is_file()
        hashes = {tm["topic_metadata"]["name"]: tm["topic_metadata"]["type_description_hash"]
                  for tm in meta["topics_with_message_count"]}
        assert hashes["/tf"] == hashes["/tf_static"] == TF_MESSAGE_HASH
        for topic, h in live_hashes.items():
            assert hashes[topic] == h, f"{topic}: the bag says {hashes[topic]}, the graph {h}"
        assert set(live_hashes) == {"/odom", "/tf", "/scan"}
        qos = {tm["topic_metadata"]["name"]: tm["topic_metadata"]["offered_qos_profiles"]
               for tm in meta["topics_with_message_count"]}
        assert qos["/tf_static"][0]["durability"] == "transient_local", "ros2 bag play republishes it latched"
    else:
        import rosbag
        from nav_msgs.msg import Odometry

        with rosbag.Bag(str(out)) as rb:  # Debian's ROS 1 reads it
            info = rb.get_type_and_topic_info().topics
            assert info["/odom"].msg_type == "nav_msgs/Odometry" and info["/odom"].message_count == len(odom)
            assert rb.get_type_and_topic_info().msg_types["nav_msgs/Odometry"] == Odometry._md5sum
