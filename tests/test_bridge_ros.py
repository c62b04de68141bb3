"""The bridge end to end against the fake simulator, on each middleware (``[ros1]``: a real roscore on a free
port; ``[ros2]``: a private ROS domain id): ``raf bridge`` as a process, the fake SimTwo (tests/fakesim.py) in a
thread of this process, and the in-process test node (rosutil). The same topics, types, frames and behaviour
on both; each middleware's own conventions (ROS 1: rosparam, rosbag; ROS 2: QoS, declared parameters, a late
subscriber's latched topics) where they differ."""
from __future__ import annotations

import math
import socket
import subprocess
import time

import numpy as np
import pytest

from fakesim import FakeSim, tick_of_image
from rosutil import (Collector, TFTree, free_port, level_int, publisher, raf_process, ros_graph, stamp_ns,  # noqa: F401
                     stamp_s, stop_process, test_node, unpublish, wait_for_node, wait_until)

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WATCHDOG = 0.5


@pytest.fixture(scope="module")
def rig(middleware, ros_graph, tmp_path_factory):
    """One bridge process and one fake simulator (lockstep, real time) shared by the tests of this file."""
    port = free_port(socket.SOCK_DGRAM)
    cam = f"tcp://127.0.0.1:{free_port()}"
    log = tmp_path_factory.mktemp("bridge") / "bridge.log"
    # the fake simulator renders on the grid k/15 s: the grid idealisation's stamping makes its stamps exact
    proc = raf_process(["bridge", "--port", str(port), "--camera", cam, "--set", "camera/bracket=nearest",
                        "--set", "camera/use_grid=true", "--set", f"watchdog/timeout={WATCHDOG}",
                        "--set", "diagnostics/period=0.25", "--set", "log_period=1.0"], ros_graph.env(), log)
    node = test_node()
    wait_for_node("/raf_bridge", 30)
    sim = FakeSim(("127.0.0.1", port), cam, lockstep=True, lockstep_timeout=0.3).start()
    yield {"node": node, "middleware": middleware, "sim": sim, "port": port, "cam": cam, "proc": proc, "log": log}
    sim.stop()
    code = stop_process(proc)
    print(log.read_text()[-4000:])
    assert code == 0, f"raf bridge exited with {code}"


def diag_values(msg, suffix):
    for st in msg.status:
        if st.name.endswith(suffix):
            return st, {kv.key: kv.value for kv in st.values}
    raise KeyError(suffix)


def latest_diag(diag: Collector, suffix: str, after: float = 0.0):
    def has(m):
        return any(s.name.endswith(suffix) for s in m.status)

    msgs = diag.wait(1, timeout=5, pred=has)
    with diag._lock:
        pairs = [(t, m) for t, m in zip(diag.times, diag.msgs) if t >= after and has(m)]
    if not pairs:
        return diag_values(msgs[-1], suffix)
    return diag_values(pairs[-1][1], suffix)


@pytest.mark.middlewares
def test_every_topic_arrives_with_types_frames_and_stamps(rig):
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image, JointState, LaserScan
    from std_msgs.msg import Bool
    from visualization_msgs.msg import MarkerArray

    topics = {"/clock": Clock, "/odom": Odometry, "/ground_truth": Odometry, "/joint_states": JointState,
              "/scan": LaserScan, "/contact": Bool, "/electromagnet/state": Bool, "/camera/image_raw": Image,
              "/camera/camera_info": CameraInfo, "/field/markers": MarkerArray, "/diagnostics": DiagnosticArray}
    cols = {t: Collector(t, ty) for t, ty in topics.items()}
    try:
        for t, c in cols.items():
            c.wait({"/field/markers": 1, "/scan": 3, "/camera/image_raw": 45, "/diagnostics": 4}.get(t, 5), timeout=20)
    finally:
        for c in cols.values():
            c.close()
    m = {t: c.msgs for t, c in cols.items()}
    # /clock follows Tms: whole control periods, increasing
    clocks = [stamp_ns(c.clock) for c in m["/clock"]]
    assert all(b > a for a, b in zip(clocks, clocks[1:]))
    assert all(c % 40_000_000 == 0 for c in clocks)
    od = m["/odom"][-1]
    assert (od.header.frame_id, od.child_frame_id) == ("odom", "base_link")
    assert stamp_ns(od.header.stamp) % 40_000_000 == 0
    cov = np.array(od.pose.covariance).reshape(6, 6)
    assert np.all(np.diag(cov) > 0)
    gt = m["/ground_truth"][-1]
    assert gt.header.frame_id == "map" and gt.child_frame_id == "base_link"
    js = m["/joint_states"][-1]
    assert list(js.name) == ["left_wheel_joint", "right_wheel_joint"] and len(js.position) == 2
    assert stamp_ns(js.header.stamp) % 40_000_000 == 0
    sc = m["/scan"][-1]
    assert sc.header.frame_id == "laser"
    assert sc.angle_min == pytest.approx(-math.pi) and sc.angle_max == pytest.approx(math.pi)
    assert sc.angle_increment == pytest.approx(2 * math.pi / 359)
    assert sc.range_max == 6.0 and sc.scan_time == pytest.approx(0.2)
    assert sc.time_increment == pytest.approx(0.2 / 360, rel=0.01)
    assert len(sc.ranges) == 360 and math.isinf(sc.ranges[7])
    assert sc.ranges[100] == pytest.approx(1.1, abs=1e-6)
    # a sweep is stamped with the time of its first ray: the fake simulator delivers whole sweeps 1 ms after
    # a cycle's end like SimTwo (measured over the period before), which lidar/delivery_lag assumes
    for s in m["/scan"]:
        assert (stamp_ns(s.header.stamp) - 1_000_000) % 200_000_000 == 0, stamp_s(s.header.stamp)
    assert m["/contact"][-1].data is False
    img = m["/camera/image_raw"]
    for im in img:
        assert (im.encoding, im.width, im.height, im.step, im.header.frame_id) == ("bgr8", 640, 480, 1920,
                                                                                   "camera_optical")
    # stamps: the render time of each frame (the fake simulator writes its render tick into the image)
    from robotatfactory.ros.messages import camera_matrices, image_to_bgr

    truth = [tick_of_image(image_to_bgr(im)) / 60 for im in img]
    stamps = [stamp_s(im.header.stamp) for im in img]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    late = list(zip(truth, stamps))[-12:]  # after the render phase has been learned
    wrong = [(t, s) for t, s in late if s != pytest.approx(t, abs=1e-6)]
    cam = [{kv.key: kv.value for kv in st.values} for d in m["/diagnostics"] for st in d.status
           if st.name.endswith(": camera")]
    assert not wrong, f"wrong stamps {wrong}; camera diagnostics {cam[-1] if cam else None}"
    # the image is right side up: the fake frame's tick lives in the TOP row, which arrived as the last row
    bgr = image_to_bgr(img[-1])
    assert tuple(bgr[240, 320]) == (200, 50, 20) and tuple(bgr[479, 639]) == (0, 80, 0)
    info = m["/camera/camera_info"][-1]
    assert camera_matrices(info)[1] == [226.8, 0, 319.5, 0, 226.8, 239.5, 0, 0, 1]
    assert info.header.frame_id == "camera_optical"
    # camera_info carries its image's stamp. Not asserted for the very last image: its camera_info is published
    # right after it and may not have arrived when the collectors closed (and on ROS 2 both are best effort)
    infos = {stamp_ns(i.header.stamp) for i in m["/camera/camera_info"]}
    matched = infos & {stamp_ns(im.header.stamp) for im in img}
    assert len(matched) >= len(img) // 2, (len(matched), len(img))
    arr = m["/field/markers"][0]
    ns = {mk.ns for mk in arr.markers}
    assert {"floor", "walls", "slots", "aruco", "aruco_ids"} <= ns
    assert sum(mk.ns == "aruco" for mk in arr.markers) == 49
    stream = [d for d in m["/diagnostics"] if any(x.name.endswith("sensor stream") for x in d.status)]
    st, vals = diag_values(stream[-1], "sensor stream")
    assert int(vals["accepted"]) > 0 and float(vals["datagram_rate_hz"]) > 10


@pytest.mark.middlewares
def test_tf_resolves_markers_and_camera(rig):
    from robotatfactory.robot import load_robot

    tf = TFTree()
    try:
        T = tf.lookup("map", "aruco_13", 10)
        assert T[:3, 3] == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
        assert tf.can_transform("odom", "camera_optical", 10)
        # the optical frame is the camera mount: z forward-down
        cam = load_robot().camera
        B = tf.lookup("base_link", "camera_optical", 5)
        assert np.allclose(B[:3, :3], cam.base_to_optical()[:3, :3], atol=1e-9)
        assert (B[0, 3], B[2, 3]) == pytest.approx((cam.xyz[0], cam.xyz[2]))
        assert tf.can_transform("base_link", "left_wheel", 5)
        assert tf.can_transform("base_link", "laser", 5)
        # odom -> base_link is dynamic and stamped with simulation time (whole control periods)
        _, stamp = tf.try_lookup("odom", "base_link")
        assert stamp is not None and round(stamp * 1e9) % 40_000_000 == 0
    finally:
        tf.close()
    if rig["middleware"] == "ros1":  # and ROS 1's own TF library resolves the same tree
        import rospy
        import tf2_ros

        buf = tf2_ros.Buffer()
        listener = tf2_ros.TransformListener(buf)
        t = buf.lookup_transform("map", "aruco_13", rospy.Time(0), rospy.Duration(10))
        assert t.transform.translation.x == pytest.approx(0.0, abs=1e-9)
        assert buf.can_transform("odom", "camera_optical", rospy.Time(0), rospy.Duration(10))
        listener.unregister()


@pytest.mark.middlewares
def test_latched_topics_reach_a_late_subscriber_and_qos(rig):
    """/tf_static and /field/markers, published once at start-up, reach a subscriber that comes much later
    (ROS 1: latched; ROS 2: reliable + transient local). ROS 2: what each publisher offers is asserted: the
    sensor topics best effort, the control path and odometry reliable."""
    from tf2_msgs.msg import TFMessage
    from visualization_msgs.msg import MarkerArray

    wait_until(lambda: len(rig["sim"].received) > 20, 10, what="the stream running")
    static, markers = Collector("/tf_static", TFMessage), Collector("/field/markers", MarkerArray)
    try:
        frames = {t.child_frame_id for m in static.wait(1, timeout=10) for t in m.transforms}
        assert {"aruco_13", "laser", "camera_optical"} <= frames, frames
        assert sum(mk.ns == "aruco" for mk in markers.wait(1, timeout=10)[0].markers) == 49
    finally:
        static.close()
        markers.close()
    if rig["middleware"] == "ros2":
        from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

        from rosutil import publisher_qos, subscription_qos

        def offered(topic):
            q = wait_until(lambda: publisher_qos(topic), 5, what=f"a publisher of {topic}")
            return {(p.reliability, p.durability) for p in q}

        for topic in ("/scan", "/camera/image_raw", "/camera/camera_info"):
            assert {r for r, _ in offered(topic)} == {ReliabilityPolicy.BEST_EFFORT}, topic
        for topic in ("/tf_static", "/field/markers"):
            assert offered(topic) == {(ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL)}, topic
        for topic in ("/odom", "/tf", "/clock", "/diagnostics"):
            assert {r for r, _ in offered(topic)} == {ReliabilityPolicy.RELIABLE}, topic
        cmd = subscription_qos("/cmd_vel")
        assert cmd and all(q.reliability == ReliabilityPolicy.RELIABLE for q in cmd), cmd


@pytest.mark.middlewares
def test_parameters_and_sim_time(rig):
    """The bridge's settings as each middleware shows parameters. ROS 1: on the master (``rosparam get``),
    ``/use_sim_time`` set; ROS 2: declared on the node with the YAML's comment as description and the checked
    range (``ros2 param describe``), ``use_sim_time`` a parameter of the node."""
    if rig["middleware"] == "ros1":
        import rospy

        assert rospy.get_param("/raf_bridge/watchdog/timeout") == WATCHDOG
        assert rospy.get_param("/raf_bridge/diagnostics/period") == 0.25
        assert rospy.get_param("/use_sim_time") is True
        return
    from rcl_interfaces.msg import ParameterType

    from rosutil import node_parameters

    p = node_parameters("/raf_bridge")
    assert p["use_sim_time"][0] is True
    value, d = p["watchdog.timeout"]
    assert value == WATCHDOG and d.type == ParameterType.PARAMETER_DOUBLE
    assert "SIMULATION time" in d.description
    assert d.floating_point_range and d.floating_point_range[0].from_value >= 0
    assert p["diagnostics.period"][0] == 0.25 and p["camera.use_grid"][0] is True
    assert p["udp.port"][1].type == ParameterType.PARAMETER_INTEGER and p["udp.port"][1].integer_range
    described = [n for n, (_, d) in p.items() if d.description]
    assert len(p) >= 40 and len(described) >= 0.5 * len(p), sorted(set(p) - set(described))
    assert {"udp.port", "watchdog.timeout", "diagnostics.period", "frame_prefix"} <= set(described)


@pytest.mark.middlewares
def test_cmd_vel_moves_the_robot_and_the_watchdog_stops_it(rig):
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry

    sim = rig["sim"]
    pub = publisher("/cmd_vel", Twist)
    odom = Collector("/odom", Odometry)
    x0 = sim.pose()[0]
    tw = Twist()
    tw.linear.x, tw.angular.z = 0.2, 0.5
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        pub.publish(tw)
        time.sleep(0.05)
    x1, _, th1 = sim.pose()
    assert x1 - x0 > 0.1  # 0.2 m/s for ~1.5 s, turning
    got = [r for r in sim.received[-10:]]
    assert all(r.v == pytest.approx(0.2) and r.w == pytest.approx(0.5) for r in got)
    # odometry follows: speed and turn rate measured from the encoders
    od = odom.wait(10)[-1]
    assert od.twist.twist.linear.x == pytest.approx(0.2, abs=0.02)
    assert od.twist.twist.angular.z == pytest.approx(0.5, abs=0.15)
    # stop publishing: after the watchdog timeout (simulation time) the replies say V = W = 0
    t_stop = time.monotonic()
    wait_until(lambda: sim.received[-1].v == 0.0 and sim.received[-1].w == 0.0, 5, what="watchdog stop")
    stopped_after = time.monotonic() - t_stop
    assert WATCHDOG - 0.1 <= stopped_after <= WATCHDOG + 0.6
    x2 = sim.pose()[0]
    time.sleep(0.5)
    assert sim.pose()[0] == pytest.approx(x2, abs=1e-9)
    odom.close()
    unpublish(pub)


@pytest.mark.middlewares
def test_electromagnet_command_reaches_the_simulator(rig):
    from std_msgs.msg import Bool

    sim = rig["sim"]
    pub = publisher("/electromagnet", Bool)
    state = Collector("/electromagnet/state", Bool)
    pub.publish(Bool(data=True))
    wait_until(lambda: sim.received and sim.received[-1].magnet, 5, what="S = 1 in the replies")
    state.wait(1, timeout=5, pred=lambda m: m.data)
    pub.publish(Bool(data=False))
    wait_until(lambda: not sim.received[-1].magnet, 5, what="S = 0 in the replies")
    state.close()
    unpublish(pub)


@pytest.mark.middlewares
def test_exactly_one_reply_per_datagram_with_seq_echoed(rig):
    sim = rig["sim"]
    n0 = len(sim.received)
    time.sleep(1.0)
    new = sim.received[n0:]
    seqs = [r.seq for r in new]
    assert len(seqs) >= 20
    assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))  # one each, in order, none missing


@pytest.mark.middlewares
def test_bad_input_is_counted_and_good_frames_keep_flowing(rig):
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry

    from robotatfactory.simtwo import SensorFrame

    sim, port = rig["sim"], rig["port"]
    diag = Collector("/diagnostics", DiagnosticArray)
    _, before = latest_diag(diag, "sensor stream")
    _, cam_before = latest_diag(diag, "camera")
    odom = Collector("/odom", Odometry)
    # foreign source: 127.0.0.2 is loopback too, but not the accepted simulator host
    foreign = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    foreign.bind(("127.0.0.2", 0))
    good = SensorFrame(seq=5, time_ms=240, enc_delta=(0, 0), enc_total=(0, 0), x=0, y=0, theta=0, contact=False,
                       magnet=False).encode()
    foreign.sendto(good, ("127.0.0.1", port))
    foreign.close()
    sim.send(b"RAF\r\n1\r\n\r\nSeq\r\nbanana\r\n\r\n")  # malformed
    sim.send(b"\xff\xfe garbage")  # malformed (not ASCII)
    sim.send(b"V\r\n0.3\r\n\r\n")  # foreign protocol (no RAF label)
    sim.send(b"RAF\r\n2\r\n\r\n")  # foreign protocol (another version)
    sim.send(b"X" * 20000)  # oversized
    sim.publish_camera(0, nbytes=1000)  # wrong-sized camera frame
    last = sim.seq - 1
    old = SensorFrame(seq=max(0, last - 3), time_ms=max(40, (last - 2) * 40), enc_delta=(0, 0), enc_total=(0, 0),
                      x=0, y=0, theta=0, contact=False, magnet=False)
    sim.send(old.encode())  # out of order
    t_bad = time.monotonic()
    odom.wait(10, timeout=10)  # good frames keep flowing
    wait_until(lambda: latest_diag(diag, "sensor stream", t_bad + 0.3)[1].get("rejected_oversized") !=
               before["rejected_oversized"], 5, what="diagnostics updated")
    time.sleep(0.6)
    st, after = latest_diag(diag, "sensor stream", time.monotonic() - 0.3)
    d = {k: int(after[k]) - int(before[k]) for k in ("rejected_malformed", "rejected_foreign_source",
                                                     "rejected_foreign_protocol", "rejected_oversized", "stale")}
    assert d == {"rejected_malformed": 2, "rejected_foreign_source": 1, "rejected_foreign_protocol": 2,
                 "rejected_oversized": 1, "stale": 1}
    # the camera process rejects the wrong-sized frame for its size, or, when its publisher thread is behind
    # (ROS 2's publish of an image takes longer), drops it unread because the next frame replaced it in the
    # mailbox (camera_node keeps only the newest: counted as skipped). Either way it is counted, never published.
    def cam_delta(v):
        return {k: int(v[k]) - int(cam_before[k]) for k in ("rejected_wrong_size", "skipped")}

    wait_until(lambda: any(cam_delta(latest_diag(diag, "camera", t_bad)[1]).values()), 5,
               what="the camera's diagnostics counting the wrong-sized frame")
    time.sleep(0.6)
    _, cam_after = latest_diag(diag, "camera", time.monotonic() - 0.3)
    d_cam = cam_delta(cam_after)
    assert d_cam["rejected_wrong_size"] == 1 or (d_cam["rejected_wrong_size"] == 0 and d_cam["skipped"] >= 1), d_cam
    # the node is alive and still publishing
    n = len(odom.msgs)
    odom.wait(n + 5, timeout=5)
    assert rig["proc"].poll() is None
    # the bad input is in the log, rate-limited
    text = rig["log"].read_text()
    assert "20000-byte" in text and "127.0.0.2" in text and "banana" in text
    diag.close()
    odom.close()


@pytest.mark.middlewares
def test_lost_datagrams_lose_no_ticks(rig):
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry

    sim = rig["sim"]
    pub = publisher("/cmd_vel", Twist)
    odom = Collector("/odom", Odometry)
    od0 = odom.wait(1)[-1]
    wait_until(lambda: len(odom.msgs) > 1, 5)
    lost0 = sim.lost
    x0 = sim.pose()
    tw = Twist()
    tw.linear.x = 0.25
    sim.loss = 0.3
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        pub.publish(tw)
        time.sleep(0.05)
    sim.loss = 0.0
    pub.publish(Twist())
    time.sleep(0.3)
    n = len(odom.msgs)
    odom.wait(n + 3)
    x1 = sim.pose()
    assert sim.lost - lost0 >= 5
    od1 = odom.msgs[-1]
    dist_true = math.hypot(x1[0] - x0[0], x1[1] - x0[1])
    dist_odom = math.hypot(od1.pose.pose.position.x - od0.pose.pose.position.x,
                           od1.pose.pose.position.y - od0.pose.pose.position.y)
    assert dist_true > 0.15  # it drove (0.25 m/s for 1.5 s less the cycles lost; 0.19999 seen on ROS 2 under load)
    tick = 2 * math.pi * 0.0325 / 360
    assert abs(dist_odom - dist_true) < 2 * tick  # every tick counted despite the lost datagrams
    odom.close()
    unpublish(pub)


@pytest.mark.middlewares
def test_stale_simulator_is_reported_and_recovers_including_a_restart(rig):
    from diagnostic_msgs.msg import DiagnosticArray

    from robotatfactory.ros.mw.base import ERROR, OK
    from nav_msgs.msg import Odometry

    sim = rig["sim"]
    diag = Collector("/diagnostics", DiagnosticArray)
    wait_until(lambda: sim.seq > 60, 10, what="a simulator that has run a while")  # then a restart is no replay
    sim.pause()
    try:  # (the rig's simulator is shared: never left paused for the tests after this one)
        t0 = time.monotonic()
        wait_until(lambda: level_int(latest_diag(diag, "sensor stream", t0 + 2.2)[0].level) == ERROR, 6,
                   what="stale ERROR")
        _, vals = latest_diag(diag, "sensor stream")
        # ERROR is staleness > stale_error (2.0 s); the value is published to 3 decimals, so 2.0004 s reads "2.000"
        assert float(vals["staleness_s"]) >= 2.0
        _, before = latest_diag(diag, "sensor stream")
        # the simulator comes back restarted: Seq and time from 0
        odom = Collector("/odom", Odometry)
        sim.reset(0)
    finally:
        sim.resume()
    t1 = time.monotonic()
    wait_until(lambda: level_int(latest_diag(diag, "sensor stream", t1 + 0.3)[0].level) == OK, 6,
               what="OK after recovery")
    _, after = latest_diag(diag, "sensor stream", t1 + 0.3)
    assert int(after["restarts"]) == int(before["restarts"]) + 1
    msgs = odom.wait(5)
    # odometry restarted from the origin and the clock went back with the simulator
    assert stamp_s(msgs[-1].header.stamp) < 3.0
    assert abs(msgs[-1].pose.pose.position.x) < 0.05
    diag.close()
    odom.close()


def test_rosbag_record_plays_back(rig, tmp_path):
    """ROS 1 only (rosbag; the ROS 2 recording is ``raf record``'s, tested with it)."""
    from nav_msgs.msg import Odometry

    bag_path = tmp_path / "bridge.bag"
    topics = ["/odom", "/scan", "/tf", "/tf_static", "/clock", "/camera/image_raw", "/camera/camera_info",
              "/joint_states", "/ground_truth"]
    env = __import__("rosutil").master().env()
    rec = subprocess.Popen(["rosbag", "record", "-O", str(bag_path), *topics], env=env,
                           stdout=open(tmp_path / "rosbag.log", "wb"), stderr=subprocess.STDOUT, start_new_session=True)
    try:
        active = bag_path.with_name(bag_path.name + ".active")
        wait_until(active.exists, 30, what="rosbag recording")  # subscribed and writing
        odom = Collector("/odom", Odometry)
        time.sleep(4.0)
        odom.close()
    finally:
        code = stop_process(rec)
    # the rosbag command runs the recorder as a child, which closes (renames) the bag after the parent exits
    wait_until(bag_path.exists, 15, what=f"the closed bag (rosbag exited {code})")
    import rosbag

    with rosbag.Bag(str(bag_path)) as bag:
        info = bag.get_type_and_topic_info()
        counts = {t: v.message_count for t, v in info.topics.items()}
        types = {t: v.msg_type for t, v in info.topics.items()}
        odoms = [m for _, m, _ in bag.read_messages(topics=["/odom"])]
        imgs = [m for _, m, _ in bag.read_messages(topics=["/camera/image_raw"])]
    assert types["/odom"] == "nav_msgs/Odometry" and types["/scan"] == "sensor_msgs/LaserScan"
    assert types["/camera/image_raw"] == "sensor_msgs/Image"
    assert counts["/odom"] >= 40 and counts["/scan"] >= 5 and counts["/camera/image_raw"] >= 20
    assert counts["/tf_static"] >= 1
    stamps = [o.header.stamp.to_sec() for o in odoms]
    assert all(b > a for a, b in zip(stamps, stamps[1:]))
    assert imgs[0].encoding == "bgr8" and len(imgs[0].data) == 640 * 480 * 3
