"""The localization node under ROS (its own roscore on a free port, or a ROS 2 domain of its own): synthetic
camera images of a robot driving a known straight line, its odometry, a LIDAR scan of the beacons and some
garbage; the node's outputs checked against the known answers. The first test runs on either middleware
(rosutil's test node); the second starts the node with roslaunch (ROS 1)."""
import math
import time

import numpy as np
import pytest

from rosutil import (Collector, publisher, raf_process, ros_master, stamp_s, stop_process, test_node,  # noqa: F401
                     unpublish, wait_until)

from robotatfactory.ros.mw import QoS

pytestmark = [pytest.mark.ros, pytest.mark.slow]

START = (-0.5, -0.35, math.pi / 2 - 0.3)  # true start pose in map; odometry starts at (0, 0, 0) in odom
V = 0.08  # m/s along the heading


def truth(t):
    return (START[0] + V * t * math.cos(START[2]), START[1] + V * t * math.sin(START[2]), START[2])


@pytest.fixture(scope="module")
def node(middleware, ros_master, tmp_path_factory):
    log = tmp_path_factory.mktemp("loc") / "localize.log"
    proc = raf_process(["localize", "--no-sim-time", "--set", "node/diagnostics_period=0.25",
                        "--set", "node/log_period=0.5"], ros_master.env(), log)
    yield proc, log
    stop_process(proc)


@pytest.mark.middlewares
def test_node_localizes_a_robot_from_images_odometry_and_beacons(node, middleware, field, robot):
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import CameraInfo, Image, LaserScan
    from std_msgs.msg import Bool
    from tf2_msgs.msg import TFMessage
    from visualization_msgs.msg import MarkerArray

    from robotatfactory.localization.lidar import simulate_scan
    from robotatfactory.localization.synth import SceneRenderer, camera_world_pose, visible_markers
    from robotatfactory.ros import messages as rm

    proc, log = node
    test_node()
    # as the bridge publishes them: images, camera_info and scans as sensor data, odometry reliable
    pub_img = publisher("/camera/image_raw", Image, QoS.SENSOR, 5, wait_for=0)
    pub_info = publisher("/camera/camera_info", CameraInfo, QoS.SENSOR, 5, wait_for=0)
    pub_odom = publisher("/odom", Odometry, QoS.RELIABLE, 50, wait_for=0)
    pub_scan = publisher("/scan", LaserScan, QoS.SENSOR, 5, wait_for=0)
    pub_magnet = publisher("/electromagnet", Bool, QoS.CONTROL, 1, wait_for=0)  # as the agent publishes it
    pose = Collector("/pose", PoseWithCovarianceStamped)
    cam = Collector("/camera_pose", PoseWithCovarianceStamped)
    fixes = Collector("/aruco/fixes/planar", PoseWithCovarianceStamped)
    markers = Collector("/aruco/markers", MarkerArray, qos=QoS.RELIABLE)  # per frame, not latched
    debug = Collector("/aruco/debug_image", Image)
    tf = Collector("/tf", TFMessage)
    diag = Collector("/diagnostics", DiagnosticArray)
    wait_until(lambda: pub_odom.subscriber_count() and pub_img.subscriber_count() and pub_scan.subscriber_count()
               and pub_magnet.subscriber_count() and _publishers(pose.sub) and _publishers(debug.sub), timeout=30,
               what="the node's subscriptions")
    rend = SceneRenderer(field, robot.camera)

    def img_msg(img, t):
        return rm.image_bgr8(rm.stamp_s(t), "camera_optical", img.tobytes(), img.shape[1], img.shape[0])

    def odom_msg(t):
        m = Odometry()
        m.header.stamp = rm.stamp_s(t)
        m.header.frame_id, m.child_frame_id = "odom", "base_link"
        m.pose.pose.position.x = float(V * t)  # odometry: straight along its own x, from its own origin
        m.pose.pose.orientation.w = 1.0
        return m

    info = CameraInfo()
    rm.set_camera_matrices(info, [], [float(v) for v in robot.camera.K.ravel()], [0.0] * 9, [0.0] * 12)
    rng = np.random.default_rng(0)
    t = 0.04
    k = 0
    while t < 4.0:
        pub_odom.publish(odom_msg(t))
        if k % 3 == 1:  # a camera frame rendered 20 ms ago, delivered now (late, stamped at its render time)
            tc = t - 0.02
            pub_info.publish(info)
            pub_img.publish(img_msg(rend.render(truth(tc), blur_sigma=0.5, noise_sigma=2, rng=rng), tc))
        if k % 5 == 0:
            scan = LaserScan()
            scan.header.stamp = rm.stamp_s(t)
            angles = robot.lidar.angles()
            scan.angle_min, scan.angle_increment = float(angles[0]), float(angles[1] - angles[0])
            scan.range_min, scan.range_max = 0.02, 6.0
            r = simulate_scan(truth(t), field.beacons, field.beacon_diameter, angles, rng=rng)
            scan.ranges = [float(v) for v in np.where(r < 0, np.inf, r)]
            pub_scan.publish(scan)
        if k >= 20:  # the agent switches its magnet on at 0.84 s and says so every cycle: the filter carries
            pub_magnet.publish(Bool(data=True))
        if k == 41:  # garbage: a truncated image, a wrong encoding (between two frames), a NaN odometry
            bad = img_msg(np.zeros((480, 640, 3), np.uint8), t)
            bad.data = bad.data[:1000]
            pub_img.publish(bad)
        if k == 44:
            bad2 = img_msg(np.zeros((480, 640, 3), np.uint8), t)
            bad2.encoding = "yuv422"
            pub_img.publish(bad2)
            nan = odom_msg(t)
            nan.pose.pose.position.y = float("nan")
            pub_odom.publish(nan)
        time.sleep(0.04)
        t += 0.04
        k += 1
    got = pose.wait(20, timeout=10)
    last = pose.wait(1, timeout=5, pred=lambda m: stamp_s(m.header.stamp) > 3.9)[-1]
    tt = stamp_s(last.header.stamp)
    x, y = last.pose.pose.position.x, last.pose.pose.position.y
    assert math.hypot(x - truth(tt)[0], y - truth(tt)[1]) < 0.01
    q = last.pose.pose.orientation
    assert abs(2 * math.atan2(q.z, q.w) - START[2]) < math.radians(1)
    cov = np.array(last.pose.covariance).reshape(6, 6)
    assert 0 < cov[0, 0] < 0.01 ** 2 and np.all(np.isfinite(cov))
    # the paper's camera pose: camera_optical in map
    c = cam.wait(5, timeout=5)[-1]
    T = camera_world_pose(robot.camera, truth(stamp_s(c.header.stamp)))
    p = c.pose.pose.position
    assert math.dist((p.x, p.y, p.z), T[:3, 3]) < 0.03
    fixes.wait(5, timeout=5)
    # map -> odom is the start pose (odometry starts at the odom origin)
    mo = [tr for m in tf.msgs for tr in m.transforms if tr.header.frame_id == "map" and tr.child_frame_id == "odom"]
    assert len(mo) > 20
    tr = mo[-1].transform
    assert math.hypot(tr.translation.x - START[0], tr.translation.y - START[1]) < 0.01
    assert abs(2 * math.atan2(tr.rotation.z, tr.rotation.w) - START[2]) < math.radians(1)
    # the detected markers carry their IDs; the debug image came out at full size
    T0 = camera_world_pose(robot.camera, truth(1.0))
    near = {v.id for v in visible_markers(field, robot.camera, T0) if v.distance < 0.35}
    ids = {m.id for a in markers.msgs for m in a.markers if m.ns == "aruco_cube"}
    assert near and near <= ids
    d = debug.wait(1, timeout=5)[-1]
    assert (d.width, d.height, d.encoding) == (640, 480, "bgr8")
    # diagnostics: rejection counts by reason, bad input counted, beacons used, the node alive
    def values():
        out = {}
        for a in diag.msgs:
            for s in a.status:
                if "raf_localization" in s.name:
                    out.update({kv.key: kv.value for kv in s.values})
        return out
    v = wait_until(lambda: (lambda d: d if int(d.get("bad_image", "0")) >= 2 else None)(values()), timeout=5,
                   what="bad images in the diagnostics")
    assert int(v["bad_image"]) == 2
    assert "rejected_no_markers" in v or any(k.startswith("rejected_") for k in v)
    assert int(v["beacons_used"]) > 0
    assert int(v.get("bad_odom", "0")) == 1
    # the robot's own magnet command reached the filter: one switch, carrying now
    v = wait_until(lambda: (lambda d: d if int(d.get("magnet_commands", "0")) >= 50 else None)(values()), timeout=5,
                   what="the magnet commands in the diagnostics")
    assert int(v["carry_switches"]) == 1 and v["carrying"] == "True"
    assert proc.poll() is None
    assert len(got) >= 20
    # the settings as each middleware shows parameters: on the master (ROS 1), declared on the node (ROS 2)
    if middleware == "ros1":
        import rospy

        assert rospy.get_param("/raf_localization/node/diagnostics_period") == 0.25
    else:
        from rosutil import node_parameters

        p = node_parameters("/raf_localization", ["node.diagnostics_period", "use_sim_time"])
        assert p["node.diagnostics_period"][0] == 0.25 and p["node.diagnostics_period"][1].description
        assert p["use_sim_time"][0] is False  # --no-sim-time
    for c in (pose, cam, fixes, markers, debug, tf, diag):
        c.close()
    for pub in (pub_img, pub_info, pub_odom, pub_scan, pub_magnet):
        unpublish(pub)


def _publishers(sub) -> int:
    """How many publishers a test subscription is connected to (either middleware)."""
    return sub.get_num_connections() if hasattr(sub, "get_num_connections") else sub.get_publisher_count()


def test_launch_file_starts_the_node_with_its_settings(ros_master, tmp_path):
    """roslaunch robotatfactory localization.launch: the YAML is loaded as private parameters, the node
    accepts them and reports on /diagnostics."""
    import subprocess

    import rospy
    from diagnostic_msgs.msg import DiagnosticArray

    from rosutil import ROOT

    test_node()
    log = open(tmp_path / "roslaunch.log", "wb")
    proc = subprocess.Popen(["roslaunch", "--wait", str(ROOT / "launch" / "localization.launch"), "ns:=/launched",
                             "use_sim_time:=false", "initial_pose:=start"],
                            env=ros_master.env(), stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        diag = Collector("/diagnostics", DiagnosticArray)
        diag.wait(1, timeout=40, pred=lambda a: any("/launched/raf_localization" in s.name for s in a.status))
        assert rospy.get_param("/launched/raf_localization/node/initial_pose") == "start"
        assert rospy.get_param("/launched/raf_localization/pose/lone_marker_max_distance_m") == 0.45
        assert proc.poll() is None
    finally:
        stop_process(proc)
