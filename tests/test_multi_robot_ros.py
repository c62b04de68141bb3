"""Two robots end to end: ``raf sim --robots 2`` (lockstep, cameras on), one bridge and one localization node
per robot in namespaces robot1/robot2 with frame prefixes (as launch/multi_robot.launch starts them), a
private roscore or ROS 2 domain (the first test runs on each middleware). Both drive and both are localized on
their own TF trees."""
from __future__ import annotations

import math
import socket
import time

import pytest

from rosutil import (Collector, TFTree, call_service, publisher, raf_process, ros_graph, ros_master,  # noqa: F401
                     srv_types, stop_process, test_node, unpublish, wait_until)

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.render]

STRIDE = 10  # sim/multirunner.PORT_STRIDE


def _free_pair(kind) -> int:
    """A port p with p and p + STRIDE both free (robot 2's port is robot 1's + STRIDE)."""
    for _ in range(100):
        with socket.socket(socket.AF_INET, kind) as a, socket.socket(socket.AF_INET, kind) as b:
            a.bind(("127.0.0.1", 0))
            p = a.getsockname()[1]
            if p + STRIDE > 65535:
                continue
            try:
                b.bind(("127.0.0.1", p + STRIDE))
            except OSError:
                continue
            return p
    raise RuntimeError("no free port pair")


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


@pytest.mark.middlewares
def test_two_robots_drive_and_are_localized(middleware, ros_graph, tmp_path):
    from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
    from nav_msgs.msg import Odometry

    test_node()
    env = ros_graph.env()
    port, sim_port, cam = _free_pair(socket.SOCK_DGRAM), _free_pair(socket.SOCK_DGRAM), _free_pair(socket.SOCK_STREAM)
    procs = []
    try:
        for k in (1, 2):
            ns, off = f"robot{k}", STRIDE * (k - 1)
            extra = [] if k == 1 else ["--set", "topics/clock=clock"]  # one /clock: robot 1's bridge
            procs.append(raf_process(["bridge", "--ns", ns, "--frame-prefix", ns, "--port", str(port + off),
                                      "--camera", f"tcp://127.0.0.1:{cam + off}", "--set", "simulator/control=",
                                      *extra], env, tmp_path / f"bridge{k}.log"))
            procs.append(raf_process(["localize", "--ns", ns, "--frame-prefix", ns], env, tmp_path / f"loc{k}.log"))
        pubs = [publisher(f"/robot{k}/cmd_vel", Twist, wait_for=0) for k in (1, 2)]
        gt = [Collector(f"/robot{k}/ground_truth", Odometry) for k in (1, 2)]
        pose = [Collector(f"/robot{k}/pose", PoseWithCovarianceStamped) for k in (1, 2)]
        wait_until(lambda: all(p.subscriber_count() for p in pubs)
                   and all(c.publishers() for c in pose), 40, what="bridges and localization nodes")
        procs.append(raf_process(["sim", "--robots", "2", "--port", str(sim_port), "--bridge",
                                  f"127.0.0.1:{port}", "--camera-bind", f"tcp://127.0.0.1:{cam}", "--no-server",
                                  "--lockstep", "--realtime", "--lockstep-timeout", "3", "--status-every", "5"],
                                 env, tmp_path / "sim.log"))
        for c in pose:
            c.wait(1, timeout=40)  # each node localized its robot from its own camera
        for c in gt:  # a pose arriving first does not mean this subscription has met its publisher (ROS 2)
            c.wait(1, timeout=10)
        starts = [c.msgs[-1].pose.pose.position for c in gt]
        # both drive: robot 1 straight ahead, robot 2 forward and turning right (away from robot 1)
        cmds = [(0.1, 0.0), (0.08, -0.25)]
        end = time.monotonic() + 4.0
        while time.monotonic() < end:
            for p, (v, w) in zip(pubs, cmds):
                t = Twist()
                t.linear.x, t.angular.z = v, w
                p.publish(t)
            time.sleep(0.05)
        time.sleep(1.0)  # a second of fixes after the stop
        tftree = TFTree()
        for k in (1, 2):
            g = gt[k - 1].msgs[-1].pose.pose
            moved = math.hypot(g.position.x - starts[k - 1].x, g.position.y - starts[k - 1].y)
            assert 0.2 < moved < 0.55, (k, moved)
            # the localization node's estimate of robot k agrees with robot k's ground truth
            est = pose[k - 1].msgs[-1].pose.pose
            err = math.hypot(est.position.x - g.position.x, est.position.y - g.position.y)
            print(f"robot{k}: moved {moved:.3f} m, localization error {err * 1000:.1f} mm")
            assert err < 0.05, (k, err, (est.position.x, est.position.y), (g.position.x, g.position.y))
            dth = (_yaw(est.orientation) - _yaw(g.orientation) + math.pi) % (2 * math.pi) - math.pi
            assert abs(dth) < 0.1, (k, dth)
            # its own TF tree: map -> robotk/odom (localization) -> robotk/base_link (bridge)
            T = tftree.lookup("map", f"robot{k}/base_link", 10)
            assert math.hypot(T[0, 3] - g.position.x, T[1, 3] - g.position.y) < 0.06, (k, T[:2, 3])
        tftree.close()
        p1, p2 = (c.msgs[-1].pose.pose.position for c in gt)
        assert math.hypot(p1.x - p2.x, p1.y - p2.y) > 0.1  # two robots, not one seen twice
        # robot 2's sim/set_robot_pose (through the teleport labels of its Commands) moves robot 2 only
        r = call_service("/robot2/sim/set_robot_pose", srv_types().SetRobotPose, 10, x=0.3, y=-0.2, theta=0.5)
        assert r.success, r.message
        g2 = gt[1].msgs[-1].pose.pose.position
        g1 = gt[0].msgs[-1].pose.pose.position
        assert math.hypot(g2.x - 0.3, g2.y + 0.2) < 0.01 and math.hypot(g1.x - p1.x, g1.y - p1.y) < 0.005
        for c in (*gt, *pose):
            c.close()
        for p in pubs:
            unpublish(p)
    finally:
        codes = [stop_process(p) for p in reversed(procs)]
    assert codes[0] == 0, (tmp_path / "sim.log").read_text()[-3000:]


@pytest.mark.parametrize("n", [1, 2, 4])
def test_multi_robot_launch_starts_a_bridge_and_a_localization_node_per_robot(ros_master, n):
    import subprocess

    import yaml

    from rosutil import ROOT

    env = ros_master.env()
    launch = str(ROOT / "launch" / "multi_robot.launch")
    nodes = subprocess.run(["roslaunch", "--nodes", launch, f"robots:={n}"], env=env, capture_output=True,
                           text=True, timeout=60)
    assert nodes.returncode == 0, nodes.stderr
    want = {"/raf_sim"} | {f"/robot{k}/raf_{what}" for k in range(1, n + 1) for what in ("bridge", "localization")}
    assert set(nodes.stdout.split()) == want
    dump = subprocess.run(["roslaunch", "--dump-params", launch, f"robots:={n}", "port:=9810", "camera_port:=9899"],
                          env=env, capture_output=True, text=True, timeout=60)
    params = yaml.safe_load(dump.stdout)
    for k in range(1, n + 1):
        b = f"/robot{k}/raf_bridge/"
        assert params[b + "frame_prefix"] == params[f"/robot{k}/raf_localization/frame_prefix"] == f"robot{k}"
        assert params[b + "udp/port"] == 9810 + 10 * (k - 1)  # as raf sim --robots derives them
        assert params[b + "camera/endpoint"] == f"tcp://127.0.0.1:{9899 + 10 * (k - 1)}"
        assert params[b + "topics/clock"] == ("/clock" if k == 1 else "clock")  # one /clock
    args = subprocess.run(["roslaunch", "--args", "/raf_sim", launch, f"robots:={n}"], env=env, capture_output=True,
                          text=True, timeout=60)
    assert f"sim --robots {n} " in args.stdout
    # RViz shows every robot's odometry, ground truth, localization and scan
    rv = yaml.safe_load((ROOT / "rviz" / "multi_robot.rviz").read_text())
    groups = {d["Name"]: d for d in rv["Visualization Manager"]["Displays"] if d["Class"] == "rviz/Group"}
    for k in range(1, 5):
        topics = {d.get("Topic") or d.get("Image Topic") for d in groups[f"robot{k}"]["Displays"]}
        assert {f"/robot{k}/{t}" for t in ("odom", "ground_truth", "pose", "scan", "camera/image_raw")} <= topics
