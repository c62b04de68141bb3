"""raf referee's node: the factory, the machines and the score from reported positions (the real SimTwo's),
on either middleware. The node runs in the test process on the test node; the test plays the bridge (it
publishes ground_truth and ground_truth/parts) and serves sim/place_part as the bridge would."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

from robotatfactory.ros.mw import QoS

from rosutil import middleware, publisher, ros_master, srv_types, test_node, wait_until  # noqa: F401

pytestmark = [pytest.mark.ros]


@pytest.mark.middlewares
def test_referee_scores_runs_the_machines_and_serves_the_factory(middleware, ros_master, tmp_path):  # noqa: F811
    from geometry_msgs.msg import PoseArray
    from nav_msgs.msg import Odometry
    from std_msgs.msg import Bool

    from robotatfactory.competition import query
    from robotatfactory.field import load_field
    from robotatfactory.ros import messages as rm
    from robotatfactory.ros.referee_node import RefereeConfig, RefereeNode
    from robotatfactory.sim.trace import read_trace
    from robotatfactory.simtwo.teleport import part_heading

    field = load_field("simtwo2022")
    tnode = test_node()
    calls = []

    def place_part(req, resp):  # what the bridge's sim/place_part does on SimTwo, recorded
        calls.append((req.part, req.slot))
        resp.success, resp.message = True, "teleport sent"
        return resp

    srv = tnode.service("/sim/place_part", srv_types().PlacePart, place_part)
    cfg = RefereeConfig(field="simtwo2022", round=2, parts="RXXX", start_after=0.2, server_port=0,
                        trace=str(tmp_path / "trace.jsonl"), status_every=1.0)
    node = RefereeNode(cfg, tnode).start()
    pub_gt = publisher("/ground_truth", Odometry, QoS.RELIABLE, 20, wait_for=0)
    pub_parts = publisher("/ground_truth/parts", PoseArray, QoS.RELIABLE, 20, wait_for=0)
    pub_magnet = publisher("/electromagnet/state", Bool, QoS.RELIABLE, 5, wait_for=0)
    host, port = node.server.address
    robot = (0.0, -0.35, math.pi / 2)
    part = list(field.slot("incoming", 1).xy)
    facing = field.slot("incoming", 1).facing  # the plate towards the slot's facing: SimTwo's heading is 90 deg more
    k = [0]

    def cycle(n=1):
        for _ in range(n):
            k[0] += 1
            stamp = rm.stamp_ms(40 * k[0])
            pub_gt.publish(rm.odometry(stamp, "map", "base_link", *robot, 0.0, 0.0, np.zeros((3, 3)), np.zeros((2, 2))))
            time.sleep(0.002)
            pub_parts.publish(rm.planar_poses(stamp, "map", [(part[0], part[1], part_heading(facing))]))
            time.sleep(0.008)

    try:
        wait_until(lambda: pub_parts.subscriber_count() > 0 and pub_gt.subscriber_count() > 0, 15, what="subscribers")
        pub_magnet.publish(Bool(data=False))
        assert query("IWP", host, port) == "STOP"  # before the start
        cycle(10)  # 0.4 s: the run started at 0.2 s
        wait_until(lambda: node.live.factory.started, 10, what="the run's start")
        assert query("IWP", host, port) == "RXXX"
        # the red part put into machine A's first input slot: a delivery, then the machine processes it
        a_in = next(s for s in field.slots_of("machine_A") if s.role == "input")
        part[:] = a_in.xy
        cycle(5)
        wait_until(lambda: node.live.report().points == 1, 10, what="the delivery to machine A")
        assert query("MAP", host, port)[a_in.number - 1] == "R"
        # 10 s of processing (simulation time), then the teleport to the output goes through sim/place_part
        cycle(260)
        wait_until(lambda: calls, 10, what="the machine's teleport")
        out_slot = calls[0][1]
        assert calls[0][0] == 1 and out_slot.startswith("machine_A_")
        assert node.counts["teleports"] == 1
        ctl = query("CTL", host, port)
        assert ctl.startswith("T") and 0 < int(ctl[1:]) < 600
    finally:
        node.stop()
        tnode.close(srv)
    trace = read_trace(tmp_path / "trace.jsonl")
    assert trace.head["round"] == 2 and len(trace.records) >= 250
    assert trace.records[-1].pose == pytest.approx(robot, abs=1e-4)
    # the trace's parts in raf sim's trace's terms: the plate's facing, not SimTwo's heading of the body
    assert trace.records[0].parts[1][2] == pytest.approx(facing, abs=1e-4)
