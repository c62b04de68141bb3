"""The localization node under ROS (its own roscore on a free port): synthetic camera images of a robot
driving a known straight line, its odometry, a LIDAR scan of the beacons and some garbage; the node's
outputs checked against the known answers."""
import math
import time

import numpy as np
import pytest

from rosutil import Collector, raf_process, ros_master, stop_process, test_node, wait_until  # noqa: F401

pytestmark = [pytest.mark.ros, pytest.mark.slow]

START = (-0.5, -0.35, math.pi / 2 - 0.3)  # true start pose in map; odometry starts at (0, 0, 0) in odom
V = 0.08  # m/s along the heading


def truth(t):
    return (START[0] + V * t * math.cos(START[2]), START[1] + V * t * math.sin(START[2]), START[2])


@pytest.fixture(scope="module")
def node(ros_master, tmp_path_factory):
    log = tmp_path_factory.mktemp("loc") / "localize.log"
    proc = raf_process(["localize", "--no-sim-time", "--set", "node/diagnostics_period=0.25",
                        "--set", "node/log_period=0.5"], ros_master.env(), log)
    yield proc, log
    stop_process(proc)


def test_node_localizes_a_robot_from_images_odometry_and_beacons(node, field, robot):
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import CameraInfo, Image, LaserScan
    from tf2_msgs.msg import TFMessage
    from visualization_msgs.msg import MarkerArray

    from robotatfactory.localization.lidar import simulate_scan
    from robotatfactory.localization.synth import SceneRenderer, camera_world_pose, visible_markers

    proc, log = node
    test_node()
    pub_img = rospy.Publisher("/camera/image_raw", Image, queue_size=5)
    pub_info = rospy.Publisher("/camera/camera_info", CameraInfo, queue_size=5)
    pub_odom = rospy.Publisher("/odom", Odometry, queue_size=50)
    pub_scan = rospy.Publisher("/scan", LaserScan, queue_size=5)
    pose = Collector("/pose", PoseWithCovarianceStamped)
    cam = Collector("/camera_pose", PoseWithCovarianceStamped)
    fixes = Collector("/aruco/fixes/planar", PoseWithCovarianceStamped)
    markers = Collector("/aruco/markers", MarkerArray)
    debug = Collector("/aruco/debug_image", Image)
    tf = Collector("/tf", TFMessage)
    diag = Collector("/diagnostics", DiagnosticArray)
    wait_until(lambda: pub_odom.get_num_connections() and pub_img.get_num_connections()
               and pose.sub.get_num_connections() and debug.sub.get_num_connections(), timeout=30,
               what="the node's subscriptions")
    rend = SceneRenderer(field, robot.camera)

    def img_msg(img, t):
        m = Image()
        m.header.stamp = rospy.Time.from_sec(t)
        m.header.frame_id = "camera_optical"
        m.height, m.width = img.shape[:2]
        m.encoding, m.step, m.data = "bgr8", img.shape[1] * 3, img.tobytes()
        return m

    def odom_msg(t):
        m = Odometry()
        m.header.stamp = rospy.Time.from_sec(t)
        m.header.frame_id, m.child_frame_id = "odom", "base_link"
        m.pose.pose.position.x = V * t  # odometry: straight along its own x, from its own origin
        m.pose.pose.orientation.w = 1.0
        return m

    info = CameraInfo()
    info.K = robot.camera.K.ravel().tolist()
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
            scan.header.stamp = rospy.Time.from_sec(t)
            angles = robot.lidar.angles()
            scan.angle_min, scan.angle_increment = float(angles[0]), float(angles[1] - angles[0])
            scan.range_min, scan.range_max = 0.02, 6.0
            r = simulate_scan(truth(t), field.beacons, field.beacon_diameter, angles, rng=rng)
            scan.ranges = np.where(r < 0, np.inf, r).tolist()
            pub_scan.publish(scan)
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
    last = pose.wait(1, timeout=5, pred=lambda m: m.header.stamp.to_sec() > 3.9)[-1]
    tt = last.header.stamp.to_sec()
    x, y = last.pose.pose.position.x, last.pose.pose.position.y
    assert math.hypot(x - truth(tt)[0], y - truth(tt)[1]) < 0.01
    q = last.pose.pose.orientation
    assert abs(2 * math.atan2(q.z, q.w) - START[2]) < math.radians(1)
    cov = np.array(last.pose.covariance).reshape(6, 6)
    assert 0 < cov[0, 0] < 0.01 ** 2 and np.all(np.isfinite(cov))
    # the paper's camera pose: camera_optical in map
    c = cam.wait(5, timeout=5)[-1]
    T = camera_world_pose(robot.camera, truth(c.header.stamp.to_sec()))
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
    assert proc.poll() is None
    assert len(got) >= 20


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
