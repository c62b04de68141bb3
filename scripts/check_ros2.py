#!/usr/bin/env python3
"""Smoke check of the ROS 2 Jazzy environment (.venv-ros2) that scripts/bootstrap_ros2.sh builds.

Run it with that environment's interpreter:  .venv-ros2/bin/python scripts/check_ros2.py
It exits 0 and prints one line per check when everything works, or exits 1 with a message that says
what is missing. It takes a few seconds and runs on a private ROS 2 graph (localhost discovery, a ROS
domain id of its own) so it never talks to other ROS 2 processes:
  1. the message and service packages the project uses import (the ros-jazzy-* wheels, rosbags, the
     project itself), and Debian's ROS 1 Python is NOT visible (the two define the same package names);
  2. a second process (this script with --peer) publishes a tf2_msgs/TFMessage on /tf_static
     (reliable, transient local) before this one subscribes; this one must still receive it (latched),
     and the type hash seen on the graph must be real Jazzy's;
  3. this process calls the peer's robotatfactory_msgs/srv/ResetSimulation and std_srvs/srv/Trigger
     services and checks the replies.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time

# real ROS 2 Jazzy's tf2_msgs/msg/TFMessage (the build of ros2/tf2_msgs must give the same)
TF_MESSAGE_HASH = "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"
PEER_LIFETIME_S = 30.0  # the peer exits by itself after this, even if this process dies
TIMEOUT_S = 10.0        # for each wait on the graph


class CheckError(Exception):
    """A check failed; the message says what is missing."""


def _private_graph() -> None:
    """Localhost discovery on a domain id of our own (set before rclpy is imported)."""
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_STATIC_PEERS", None)
    if "RAF_CHECK_DOMAIN_ID" not in os.environ:
        # 1..100: valid on Linux for any participant count; spread by pid so parallel checks differ
        os.environ["RAF_CHECK_DOMAIN_ID"] = str(1 + os.getpid() % 100)
    os.environ["ROS_DOMAIN_ID"] = os.environ["RAF_CHECK_DOMAIN_ID"]


def _tf_static_qos():
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    return QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def check_imports() -> list[str]:
    """Import what the project's ROS 2 nodes need; return the lines to print."""
    out = []
    if sys.prefix == sys.base_prefix:
        raise CheckError("not running in a venv: run .venv-ros2/bin/python scripts/check_ros2.py")
    try:
        import rospy  # noqa: F401
    except ImportError:
        out.append("Debian's ROS 1 Python is not visible (no rospy): good")
    else:
        raise CheckError(f"rospy is importable from {rospy.__file__}: the ROS 2 venv must not see "
                         "Debian's dist-packages (was it made with --system-site-packages?)")
    wanted = {
        "rclpy": [],
        "std_msgs.msg": ["Header", "String"],
        "builtin_interfaces.msg": ["Time"],
        "geometry_msgs.msg": ["TransformStamped", "Twist", "PoseWithCovarianceStamped"],
        "nav_msgs.msg": ["Odometry", "OccupancyGrid"],
        "sensor_msgs.msg": ["Image", "LaserScan", "CameraInfo", "CompressedImage"],
        "diagnostic_msgs.msg": ["DiagnosticArray", "DiagnosticStatus", "KeyValue"],
        "visualization_msgs.msg": ["Marker", "MarkerArray"],
        "rosgraph_msgs.msg": ["Clock"],
        "rcl_interfaces.msg": ["ParameterDescriptor", "FloatingPointRange"],
        "std_srvs.srv": ["Trigger", "SetBool"],
        "tf2_msgs.msg": ["TFMessage"],
        "robotatfactory_msgs.srv": ["ResetSimulation", "StepSimulation", "SetRobotPose", "PlacePart",
                                    "GetSimulationState"],
        "simulation_interfaces.srv": ["GetSimulatorFeatures", "SpawnEntity", "SetEntityState"],
        "simulation_interfaces.action": ["SimulateSteps"],
        "rclpy.action": ["ActionServer", "ActionClient"],
        "rosbags.rosbag2": ["Writer", "Reader"],
        "rosbags.typesys": ["Stores", "get_typestore"],
        "robotatfactory": [],
    }
    import importlib
    for module, names in wanted.items():
        try:
            mod = importlib.import_module(module)
        except ImportError as exc:
            hint = {"tf2_msgs.msg": " (built from ros2/tf2_msgs by scripts/bootstrap_ros2.sh)",
                    "robotatfactory_msgs.srv": " (built from ros2/robotatfactory_msgs by "
                                               "scripts/bootstrap_ros2.sh)",
                    "simulation_interfaces.srv": " (built from ros2/simulation_interfaces by "
                                                 "scripts/bootstrap_ros2.sh)",
                    "simulation_interfaces.action": " (built from ros2/simulation_interfaces by "
                                                    "scripts/bootstrap_ros2.sh)",
                    "robotatfactory": " (pip install -e . into .venv-ros2)"}.get(module, "")
            raise CheckError(f"cannot import {module}: {exc}{hint}") from exc
        missing = [n for n in names if not hasattr(mod, n)]
        if missing:
            raise CheckError(f"{module} lacks {', '.join(missing)}")
    out.append(f"imports: {len(wanted)} modules ok")
    return out


def run_peer() -> int:
    """The second node: latch a TFMessage on /tf_static, serve ResetSimulation and Trigger."""
    import rclpy
    from geometry_msgs.msg import TransformStamped
    from robotatfactory_msgs.srv import ResetSimulation
    from std_srvs.srv import Trigger
    from tf2_msgs.msg import TFMessage

    rclpy.init()
    node = rclpy.create_node("raf_check_peer")
    pub = node.create_publisher(TFMessage, "/tf_static", _tf_static_qos())
    t = TransformStamped()
    t.header.stamp = node.get_clock().now().to_msg()
    t.header.frame_id = "base_link"
    t.child_frame_id = "camera_optical"
    t.transform.translation.x = 0.125
    t.transform.rotation.w = 1.0
    pub.publish(TFMessage(transforms=[t]))

    def reset(req, resp):
        resp.success = True
        resp.message = f"reset: round {req.round}, parts {req.parts!r}"
        return resp

    def pause(req, resp):
        resp.success = True
        resp.message = "paused"
        return resp

    node.create_service(ResetSimulation, "/raf_check/reset_simulation", reset)
    node.create_service(Trigger, "/raf_check/pause", pause)
    print("ready", flush=True)
    end = time.monotonic() + PEER_LIFETIME_S
    try:
        while rclpy.ok() and time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


def _wait(node, done, what: str) -> None:
    import rclpy
    end = time.monotonic() + TIMEOUT_S
    while not done():
        if time.monotonic() > end:
            raise CheckError(f"timed out after {TIMEOUT_S:.0f} s waiting for {what}")
        rclpy.spin_once(node, timeout_sec=0.05)


def check_graph() -> list[str]:
    """Start the peer, then receive its latched /tf_static and call its services."""
    out = []
    peer = subprocess.Popen([sys.executable, os.path.abspath(__file__), "--peer"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    import rclpy
    from robotatfactory_msgs.srv import ResetSimulation
    from std_srvs.srv import Trigger
    from tf2_msgs.msg import TFMessage
    rclpy.init()
    node = rclpy.create_node("raf_check")
    try:
        line = peer.stdout.readline().strip()  # the peer has published when it says "ready"
        if line != "ready":
            peer.kill()
            err = peer.communicate(timeout=5)[1]
            raise CheckError(f"the peer node did not start: {line!r} {err.strip()[-2000:]}")
        got: list = []
        node.create_subscription(TFMessage, "/tf_static", got.append, _tf_static_qos())
        _wait(node, lambda: got, "the latched TFMessage on /tf_static (transient local)")
        tf = got[0].transforms[0]
        if (tf.header.frame_id, tf.child_frame_id, tf.transform.translation.x) != \
                ("base_link", "camera_optical", 0.125):
            raise CheckError(f"/tf_static carried the wrong transform: {tf}")
        infos = node.get_publishers_info_by_topic("/tf_static")
        hashes = {str(i.topic_type_hash) for i in infos}
        if hashes != {TF_MESSAGE_HASH}:
            raise CheckError(f"tf2_msgs/msg/TFMessage type hash on the graph is {hashes}, real Jazzy's "
                             f"is {TF_MESSAGE_HASH}: ros2/tf2_msgs/msg/TFMessage.msg differs")
        out.append("tf2_msgs/TFMessage on /tf_static: latched and received across processes, "
                   "type hash = Jazzy's")

        client = node.create_client(ResetSimulation, "/raf_check/reset_simulation")
        _wait(node, lambda: client.service_is_ready(), "the ResetSimulation service")
        future = client.call_async(ResetSimulation.Request(round=2, parts="RGBX"))
        _wait(node, future.done, "the ResetSimulation reply")
        reply = future.result()
        if not reply.success or reply.message != "reset: round 2, parts 'RGBX'":
            raise CheckError(f"ResetSimulation replied {reply}")
        trigger = node.create_client(Trigger, "/raf_check/pause")
        _wait(node, lambda: trigger.service_is_ready(), "the Trigger service")
        future = trigger.call_async(Trigger.Request())
        _wait(node, future.done, "the Trigger reply")
        if not future.result().success:
            raise CheckError(f"Trigger replied {future.result()}")
        out.append("robotatfactory_msgs/srv/ResetSimulation and std_srvs/srv/Trigger: called across "
                   "processes")
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        if peer.poll() is None:
            peer.terminate()
            try:
                peer.wait(timeout=5)
            except subprocess.TimeoutExpired:
                peer.kill()
                peer.wait()
    return out


def main(argv: list[str]) -> int:
    _private_graph()
    if argv[1:] == ["--peer"]:
        return run_peer()
    t0 = time.monotonic()
    try:
        for step in (check_imports, check_graph):
            for line in step():
                print(f"[check-ros2] {line}")
    except CheckError as exc:
        print(f"[check-ros2] FAILED: {exc}", file=sys.stderr)
        return 1
    print(f"[check-ros2] ok (domain id {os.environ['ROS_DOMAIN_ID']}, localhost only, "
          f"{time.monotonic() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
