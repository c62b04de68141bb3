"""The agent's ROS node: inputs only pose/odom/contact (never ground truth), cmd_vel and electromagnet out,
the factory-state server over UDP, and a stop when the pose goes stale. A real roscore on a free port and
the real FactoryServer on loopback; the node runs in the test process."""
from __future__ import annotations

import time

import pytest

from rosutil import Collector, ros_master, test_node, wait_until  # noqa: F401

pytestmark = [pytest.mark.ros]


def test_node_plays_only_on_its_own_inputs_and_stops_when_they_go_stale(ros_master, field):  # noqa: F811
    rospy = test_node()
    import rosgraph
    from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
    from nav_msgs.msg import Odometry, Path
    from std_msgs.msg import Bool

    from robotatfactory.competition import Factory, FactoryServer, RoundSetup
    from robotatfactory.ros import messages as rm
    from robotatfactory.ros.agent_node import SUBSCRIBED, AgentNode, AgentNodeConfig

    factory = Factory(field, RoundSetup.make(1, parts="XBXX"))
    server = FactoryServer(factory, port=0, clock=time.monotonic).start()
    node = AgentNode(AgentNodeConfig(server_port=server.address[1])).start()
    cmds = Collector("/cmd_vel", Twist)
    magnet = Collector("/electromagnet", Bool)
    paths = Collector("/agent/path", Path)
    pub_pose = rospy.Publisher("/pose", PoseWithCovarianceStamped, queue_size=5)
    pub_odom = rospy.Publisher("/odom", Odometry, queue_size=5)
    sp = field.start_pose
    try:
        # before the start: no part list, the robot stays put (and the pose is not there yet)
        cmds.wait(10, timeout=10)
        assert all(m.linear.x == 0 and m.angular.z == 0 for m in cmds.msgs)
        factory.start(time.monotonic())

        def feed():
            now = rospy.Time.now()
            p = PoseWithCovarianceStamped()
            p.header.stamp, p.header.frame_id = now, "map"
            p.pose.pose.position.x, p.pose.pose.position.y = sp.x, sp.y
            p.pose.pose.orientation = rm.yaw_quaternion(sp.theta)
            pub_pose.publish(p)
            o = Odometry()
            o.header.stamp = now
            pub_odom.publish(o)

        def moving():
            feed()
            time.sleep(0.02)
            return node.agent.mode == "to_pick" and any(abs(m.angular.z) > 0.1 for m in cmds.msgs[-5:])

        wait_until(moving, timeout=15, what="the agent turning towards its first part")
        assert "incoming 2" in str(node.agent.task)
        path = paths.wait(1, timeout=5)[-1]
        assert path.header.frame_id == "map" and len(path.poses) >= 2
        assert not any(m.data for m in magnet.msgs)
        # the node's inputs are exactly its own sensors' topics; nobody subscribes to ground truth
        assert sorted(s.resolved_name for s in node.subscribers) == sorted(f"/{t}" for t in SUBSCRIBED)
        state = rosgraph.Master("/raf_agent_test").getSystemState()
        subscribed = {topic for topic, _ in state[1]}
        assert not any("ground_truth" in t or t.startswith("/sim") for t in subscribed), subscribed
        # the pose stops coming: within the staleness limit and the braking the commands reach zero
        stale0 = node.counts["stale_cycles"]
        time.sleep(node.cfg.max_input_age + 1.0)
        assert node.counts["stale_cycles"] > stale0
        last = cmds.msgs[-1]
        assert last.linear.x == 0 and last.angular.z == 0
    finally:
        node.stop()
        server.stop()
        for c in (cmds, magnet, paths):
            c.close()
        pub_pose.unregister()
        pub_odom.unregister()


def test_launch_parameters_are_checked():
    from robotatfactory.errors import ConfigError
    from robotatfactory.ros.agent_node import config_from_params

    cfg = config_from_params({"server_port": 19832, "max_input_age": 0.3, "field": "rules2026"})
    assert (cfg.server_port, cfg.max_input_age, cfg.server_host) == (19832, 0.3, "127.0.0.1")
    with pytest.raises(ConfigError, match="unknown agent parameter.*serverport"):
        config_from_params({"serverport": 1})
    with pytest.raises(ConfigError, match="server_port"):
        config_from_params({"server_port": 0})
    with pytest.raises(ConfigError, match="max_input_age"):
        config_from_params({"max_input_age": -1.0})
