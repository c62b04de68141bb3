"""The agent's ROS node: inputs only pose/odom/contact/scan (never ground truth), cmd_vel and electromagnet out,
the factory-state server over UDP, and a stop when the pose goes stale. A real roscore on a free port and
the real FactoryServer on loopback; the node runs in the test process, on the test node of rosutil
(:mod:`robotatfactory.ros.mw`)."""
from __future__ import annotations

import time

import pytest

from robotatfactory.ros.mw import QoS

from rosutil import Collector, middleware, publisher, ros_master, test_node, unpublish, wait_until  # noqa: F401

pytestmark = [pytest.mark.ros]


@pytest.mark.middlewares
def test_node_plays_only_on_its_own_inputs_and_stops_when_they_go_stale(middleware, ros_master, field):  # noqa: F811
    tnode = test_node()
    from geometry_msgs.msg import PoseWithCovarianceStamped, Twist
    from nav_msgs.msg import Odometry, Path
    from std_msgs.msg import Bool
    from visualization_msgs.msg import Marker, MarkerArray

    from robotatfactory.competition import Factory, FactoryServer, RoundSetup
    from robotatfactory.ros import messages as rm
    from robotatfactory.agent.settings import agent_settings
    from robotatfactory.ros.agent_node import SUBSCRIBED, AgentNode

    factory = Factory(field, RoundSetup.make(1, parts="XBXX"))
    server = FactoryServer(factory, port=0, clock=time.monotonic).start()
    node = AgentNode(agent_settings({"server": {"port": server.address[1]}}), tnode).start()
    cmds = Collector("/cmd_vel", Twist)
    magnet = Collector("/electromagnet", Bool)
    paths = Collector("/agent/path", Path)
    markers = Collector("/agent/markers", MarkerArray)
    pub_pose = publisher("/pose", PoseWithCovarianceStamped, QoS.RELIABLE, 5, wait_for=0)
    pub_odom = publisher("/odom", Odometry, QoS.RELIABLE, 5, wait_for=0)
    sp = field.start_pose
    try:
        # before the start: no part list, the robot stays put (and the pose is not there yet)
        cmds.wait(10, timeout=10)
        assert all(m.linear.x == 0 and m.angular.z == 0 for m in cmds.msgs)
        factory.start(time.monotonic())

        def feed():
            now = tnode.now()
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
        # RViz: the planned round as arrows source -> destination, the current task highlighted, the goal pose
        def showing_task(arr):
            return any(m.ns == "agent_task" for m in arr.markers) and any(m.ns == "agent_goal" for m in arr.markers)

        arr = markers.wait(1, timeout=5, pred=showing_task)[-1]
        assert arr.markers[0].action == Marker.DELETEALL
        assert all(m.header.frame_id == "map" for m in arr.markers[1:])
        plan = [m for m in arr.markers if m.ns == "agent_plan"]
        texts = {m.id: m.text for m in arr.markers if m.ns == "agent_plan_text"}
        assert plan and all(m.type == Marker.ARROW and len(m.points) == 2 for m in plan)
        assert len(texts) == len(plan) and texts[0].startswith("1: ") and "incoming 2 ->" in texts[0]
        src = field.slot("incoming", 2).xy
        assert abs(plan[0].points[0].x - src[0]) < 1e-9 and abs(plan[0].points[0].y - src[1]) < 1e-9
        # a longer plan: one arrow per Move from its source slot to its destination, numbered in order, the
        # current one (the first) highlighted: thicker and of its own colour
        from robotatfactory.agent.state import FactoryState
        from robotatfactory.agent.tasks import plan_round

        steps, _ = plan_round(node.agent.policy, FactoryState.from_letters("RGBB"), 10.0)
        moves = [s.task for s in steps if hasattr(s.task, "source")]
        big = node.marker_array(moves, moves[0], None, "to_pick")
        arrows = [m for m in big.markers if m.ns == "agent_plan"]
        labels = [m.text for m in big.markers if m.ns == "agent_plan_text"]
        assert len(arrows) == len(moves) >= 4
        for k, (mv, a, label) in enumerate(zip(moves, arrows, labels)):
            s0, s1 = field.slot(mv.source.zone, mv.source.number).xy, field.slot(mv.target.zone, mv.target.number).xy
            assert (a.points[0].x, a.points[0].y, a.points[1].x, a.points[1].y) == pytest.approx((*s0, *s1))
            assert label == f"{k + 1}: {mv.part.label} {mv.source} -> {mv.target}"
        assert all(arrows[0].scale.x > a.scale.x and arrows[0].color != a.color for a in arrows[1:])
        assert not any(m.ns == "agent_goal" for m in big.markers)  # no goal given, none shown
        head = next(m for m in arr.markers if m.ns == "agent_task" and m.type == Marker.TEXT_VIEW_FACING)
        assert "incoming 2" in head.text
        goal = next(m for m in arr.markers if m.ns == "agent_goal")
        end = path.poses[-1].pose.position
        assert (goal.pose.position.x, goal.pose.position.y) == pytest.approx((end.x, end.y), abs=1e-9)
        # the node's inputs are exactly its own sensors' topics (the LIDAR's scan among them); nobody subscribes to
        # ground truth
        assert sorted(_topic(s) for s in node.subscribers) == sorted(f"/{t}" for t in SUBSCRIBED)
        subscribed = _subscribed_topics(tnode)
        assert {f"/{t}" for t in SUBSCRIBED} <= subscribed
        assert not any("ground_truth" in t or t.startswith("/sim") for t in subscribed), subscribed
        # a LIDAR sweep reaches the agent as its Scan at the next control cycle (it looks for dropped parts in it)
        from sensor_msgs.msg import LaserScan

        pub_scan = publisher("/scan", LaserScan, QoS.SENSOR, 2, wait_for=1)
        scan = rm.laser_scan(rm.stamp_s(12.5), "laser", [0.5, -1.0, 0.25], 360.0, 0.02, 6.0, 0.2, 0.001)
        wait_until(lambda: pub_scan.publish(scan) or time.sleep(0.05) or node.agent.scan is not None,
                   timeout=10, what="the scan handed to the agent")
        got = node.agent.scan
        assert got.t0 == pytest.approx(12.5) and got.time_increment == pytest.approx(0.001)
        assert got.ranges[0] == 0.5 and got.ranges[1] == float("inf") and got.range_max == 6.0
        assert got.angle_min == pytest.approx(-3.14159265, abs=1e-6) and got.angle_increment == pytest.approx(3.14159265)
        unpublish(pub_scan)
        # the pose stops coming: within the staleness limit and the braking the commands reach zero
        stale0 = node.counts["stale_cycles"]
        time.sleep(node.cfg.max_input_age + 1.0)
        assert node.counts["stale_cycles"] > stale0
        last = cmds.msgs[-1]
        assert last.linear.x == 0 and last.angular.z == 0
    finally:
        node.stop()
        server.stop()
        for c in (cmds, magnet, paths, markers):
            c.close()
        unpublish(pub_pose)
        unpublish(pub_odom)


def _topic(sub) -> str:
    """The resolved topic of a subscription of either middleware."""
    return sub.resolved_name if hasattr(sub, "resolved_name") else sub.topic_name


def _subscribed_topics(tnode) -> set[str]:
    """Every topic someone in the graph subscribes to."""
    if middleware() == "ros2":
        n = tnode.node
        return {t for name, ns in n.get_node_names_and_namespaces()
                for t, _ in n.get_subscriber_names_and_types_by_node(name, ns)}
    import rosgraph

    return {topic for topic, _ in rosgraph.Master("/raf_agent_test").getSystemState()[1]}


def test_launch_parameters_are_checked():
    from robotatfactory.errors import ConfigError
    from robotatfactory.ros.agent_node import config_from_params

    cfg = config_from_params({"server": {"port": 19832}, "max_input_age": 0.3, "field": "rules2026",
                              "dock": {"approach_speed": 0.16}, "drive": {"k_heading": 6}})
    assert (cfg.server.port, cfg.max_input_age, cfg.server.host) == (19832, 0.3, "127.0.0.1")
    assert (cfg.dock.approach_speed, cfg.drive.k_heading, cfg.drive.v_max) == (0.16, 6.0, None)
    with pytest.raises(ConfigError, match="unknown setting.*serverport"):
        config_from_params({"serverport": 1})
    with pytest.raises(ConfigError, match=r"server.port must be a whole number in \[1, 65535\], got 0"):
        config_from_params({"server": {"port": 0}})
    with pytest.raises(ConfigError, match="max_input_age"):
        config_from_params({"max_input_age": -1.0})
    with pytest.raises(ConfigError, match="tasks.choose_by_time must be true or false"):
        config_from_params({"tasks": {"choose_by_time": "yes"}})
