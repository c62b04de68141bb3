"""The bridge's simulation services (ros/sim_services.py, srv/*.srv) through ROS: with the stand-in (``raf sim``'s
control channel: every service, bad requests, a reset that leaves TF consistent for a listener that keeps
running) and with a SimTwo-like simulator (the fake: teleports through the Command datagram's labels)."""
from __future__ import annotations

import importlib.util
import json
import math
import socket
import subprocess
import sys
import time

import pytest

from rosutil import ROOT, Collector, free_port, raf_process, ros_master, stop_process, test_node, wait_until  # noqa: F401


def test_generated_service_classes_are_up_to_date(tmp_path):
    """src/robotatfactory/srv is what srv/generate.py makes of srv/*.srv (no catkin build here)."""
    spec = importlib.util.spec_from_file_location("gen_srv", ROOT / "srv" / "generate.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    made = {p.name: p.read_text() for p in gen.generate(tmp_path)}
    committed = {p.name: p.read_text() for p in (ROOT / "src" / "robotatfactory" / "srv").glob("*.py")}
    assert made == committed
    from robotatfactory.srv import Trigger

    assert Trigger._md5sum == "937c9679a518e3a18d831e57125ea522"  # std_srvs/Trigger's: its clients work too


# a TF listener that lives through the reset, as RViz and the localization node do (sim time: raf bridge set
# /use_sim_time before this starts); one JSON line per lookup of map -> base_link
PROBE = r"""
import json, math, sys, time
import rospy, tf2_ros
rospy.init_node("tf_probe", anonymous=True, disable_signals=True)
buf = tf2_ros.Buffer()
tf2_ros.TransformListener(buf)
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    try:
        t = buf.lookup_transform("map", "base_link", rospy.Time(0))
        p, q = t.transform.translation, t.transform.rotation
        out = {"ok": True, "x": p.x, "y": p.y, "yaw": 2 * math.atan2(q.z, q.w), "stamp": t.header.stamp.to_sec()}
    except Exception as e:
        out = {"ok": False, "err": str(e)[:100]}
    out["wall"] = time.time()
    print(json.dumps(out), flush=True)
    time.sleep(0.1)
"""


def _diag_services() -> tuple[str, str]:
    """The bridge's /diagnostics: (simulator, supported sim/* services)."""
    from diagnostic_msgs.msg import DiagnosticArray

    diag = Collector("/diagnostics", DiagnosticArray)
    try:
        m = diag.wait(1, timeout=5, pred=lambda m: any(kv.key == "sim_services" for s in m.status
                                                         for kv in s.values))[0]
    finally:
        diag.close()
    kv = {v.key: v.value for s in m.status for v in s.values}
    return kv["simulator"], kv["sim_services"]


def _probe_lines(proc_out) -> list[dict]:
    return [json.loads(line) for line in proc_out.read_text().splitlines() if line.startswith("{")]


@pytest.mark.ros
@pytest.mark.slow
def test_services_with_the_stand_in(ros_master, field, tmp_path):
    import rospy
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock

    from robotatfactory.srv import (GetSimulationState, PlacePart, ResetSimulation, SetRobotPose, StepSimulation,
                                    Trigger)

    test_node()
    env = ros_master.env()
    port, sim_port = free_port(socket.SOCK_DGRAM), free_port(socket.SOCK_DGRAM)
    ctl_port = free_port(socket.SOCK_DGRAM)
    procs = [raf_process(["bridge", "--port", str(port), "--no-camera", "--set",
                          f"simulator/control=127.0.0.1:{ctl_port}"], env, tmp_path / "bridge.log"),
             raf_process(["localize", "--set", "node/initial_pose=start", "--set", "node/use_lidar=false"], env,
                         tmp_path / "localize.log")]
    probe = None
    try:
        for name in ("reset", "pause", "resume", "step", "set_robot_pose", "place_part", "get_state"):
            rospy.wait_for_service(f"/sim/{name}", timeout=30)
        gt, clock = Collector("/ground_truth", Odometry), Collector("/clock", Clock)
        pub = rospy.Publisher("/cmd_vel", Twist, queue_size=1)
        procs.append(raf_process(["sim", "--port", str(sim_port), "--control-port", str(ctl_port), "--bridge",
                                  f"127.0.0.1:{port}", "--no-camera", "--no-server", "--status-every", "0"], env,
                                 tmp_path / "sim.log"))
        gt.wait(10, timeout=30)
        srv = {n: rospy.ServiceProxy(f"/sim/{n}", t) for n, t in (
            ("reset", ResetSimulation), ("pause", Trigger), ("resume", Trigger), ("step", StepSimulation),
            ("set_robot_pose", SetRobotPose), ("place_part", PlacePart), ("get_state", GetSimulationState))}
        st = srv["get_state"]()
        assert st.success and st.simulator == "stand-in"
        assert set(st.supported) == {"reset", "pause", "resume", "step", "set_robot_pose", "place_part", "get_state"}
        parts = json.loads(st.state_json)["parts"]
        assert _diag_services() == ("stand-in", "reset pause resume step set_robot_pose place_part get_state")
        probe_out = tmp_path / "probe.out"
        probe = subprocess.Popen([sys.executable, "-c", PROBE, "60"], env=env, stdout=open(probe_out, "w"),
                                 stderr=subprocess.STDOUT, start_new_session=True)
        wait_until(lambda: any(p["ok"] for p in _probe_lines(probe_out)), 20, what="the probe's first lookup")

        # drive 2 s: the localization (odometry from the start pose) follows
        tw = Twist()
        tw.linear.x = 0.2
        end = time.monotonic() + 2.0
        while time.monotonic() < end:
            pub.publish(tw)
            time.sleep(0.05)
        pub.publish(Twist())
        time.sleep(0.3)
        before = [p for p in _probe_lines(probe_out) if p["ok"]][-1]
        sp = field.start_pose
        assert math.hypot(before["x"] - sp.x, before["y"] - sp.y) > 0.15

        # pause, step, resume
        assert srv["pause"]().success
        t1 = srv["get_state"]().time
        time.sleep(0.4)
        st = srv["get_state"]()
        assert st.paused and st.time == t1
        r = srv["step"](5)
        assert r.success, r.message
        assert srv["get_state"]().time == pytest.approx(t1 + 0.2, abs=1e-6)
        r = srv["step"](0)
        assert not r.success and "bad_argument" in r.message
        assert srv["resume"]().success
        r = srv["step"](3)
        assert not r.success and "not_paused" in r.message

        # teleport and parts, with bad requests
        tx, ty = sp.x + 0.3, sp.y + 0.05  # free floor
        r = srv["set_robot_pose"](tx, ty, 1.2)
        assert r.success, r.message
        g = gt.wait(1, timeout=5, pred=lambda m: abs(m.pose.pose.position.x - tx) < 0.01)[-1].pose.pose.position
        assert abs(g.y - ty) < 0.01
        r = srv["set_robot_pose"](9.0, 0.0, 0.0)
        assert not r.success and "out_of_field" in r.message
        pid = parts[0]["id"]
        r = srv["place_part"](part=pid, slot="outgoing_1")
        assert r.success, r.message
        s = next(s for s in field.slots if s.name == "outgoing_1")
        p = next(p for p in json.loads(srv["get_state"]().state_json)["parts"] if p["id"] == pid)
        assert p["pose"][:2] == pytest.approx(list(s.xy), abs=0.01)
        r = srv["place_part"](part=pid, slot="nowhere_9")
        assert not r.success and "unknown_slot" in r.message
        r = srv["place_part"](part=999, x=0.0, y=0.0)
        assert not r.success and "unknown_part" in r.message
        assert srv["place_part"](part=pid, remove=True).success
        r = srv["reset"](round=9)
        assert not r.success and "bad_argument" in r.message

        # reset: a new stream from t = 0; the probe's TF carries the new pose, no stale transform
        stamp_before = [p for p in _probe_lines(probe_out) if p["ok"]][-1]["stamp"]
        clock.clear()
        r = srv["reset"]()
        t_reset = time.time()
        assert r.success, r.message
        st = srv["get_state"]()
        assert st.x == pytest.approx(sp.x, abs=0.01) and st.y == pytest.approx(sp.y, abs=0.01)
        assert all(p["type"] for p in json.loads(st.state_json)["parts"])
        assert min(c.clock.to_sec() for c in clock.wait(3, timeout=5)) < 0.5  # /clock went back
        time.sleep(2.0)
        after = [p for p in _probe_lines(probe_out) if p["wall"] > t_reset + 0.8]
        assert len(after) >= 8 and all(p["ok"] for p in after), after[:3]
        assert all(math.hypot(p["x"] - sp.x, p["y"] - sp.y) < 0.02 for p in after), after[-1]
        assert all(abs(math.remainder(p["yaw"] - sp.theta, 2 * math.pi)) < 0.02 for p in after)
        assert all(p["stamp"] < stamp_before for p in after)  # the new stream's times, not the old ones
        assert after[-1]["stamp"] > after[0]["stamp"]  # and they advance
        bridge_log = (tmp_path / "bridge.log").read_text()
        assert "the stand-in" in bridge_log and "supports all" in bridge_log
    finally:
        if probe is not None:
            stop_process(probe)
        for p in procs:
            stop_process(p)


@pytest.mark.ros
@pytest.mark.slow
def test_services_with_simtwo_use_the_command_labels(ros_master, field, tmp_path):
    import rospy
    from nav_msgs.msg import Odometry

    from fakesim import FakeSim
    from robotatfactory.ros.sim_services import SIMTWO_PART_Z
    from robotatfactory.srv import GetSimulationState, PlacePart, ResetSimulation, SetRobotPose, Trigger

    test_node()
    env = ros_master.env()
    port = free_port(socket.SOCK_DGRAM)
    nobody = free_port(socket.SOCK_DGRAM)  # no control channel there: SimTwo
    bridge = raf_process(["bridge", "--port", str(port), "--no-camera", "--set",
                          f"simulator/control=127.0.0.1:{nobody}"], env, tmp_path / "bridge.log")
    sim = None
    try:
        rospy.wait_for_service("/sim/get_state", timeout=30)
        odom = Collector("/odom", Odometry)
        sim = FakeSim(bridge=("127.0.0.1", port)).start()
        odom.wait(5, timeout=20)
        st = rospy.ServiceProxy("/sim/get_state", GetSimulationState)()
        assert st.success and st.simulator == "simtwo"
        assert set(st.supported) == {"reset", "set_robot_pose", "place_part", "get_state"}
        assert st.x == pytest.approx(-0.6, abs=0.01) and st.state_json == ""
        assert _diag_services() == ("simtwo", "reset set_robot_pose place_part get_state")
        r = rospy.ServiceProxy("/sim/pause", Trigger)()
        assert not r.success and "not supported by SimTwo" in r.message
        r = rospy.ServiceProxy("/sim/set_robot_pose", SetRobotPose)(0.2, 0.1, 1.0)
        assert r.success, r.message
        assert sim.pose() == pytest.approx((0.2, 0.1, 1.0), abs=1e-6)
        r = rospy.ServiceProxy("/sim/place_part", PlacePart)(part=2, slot="machine_A_1")
        assert r.success, r.message
        s = next(s for s in field.slots if s.name == "machine_A_1")
        tp = sim.teleports[-1]
        assert tp.target == "Part2" and (tp.x, tp.y, tp.z) == pytest.approx((*s.xy, SIMTWO_PART_Z), abs=1e-6)
        assert math.remainder(tp.theta - s.facing - math.pi / 2, 2 * math.pi) == pytest.approx(0, abs=1e-5)  # %.6g
        r = rospy.ServiceProxy("/sim/place_part", PlacePart)(part=2, slot="machine_A_1", type="R")
        assert not r.success and "recolour" in r.message
        # reset: the robot back to the field's start, odometry from zero there
        r = rospy.ServiceProxy("/sim/reset", ResetSimulation)()
        assert r.success, r.message
        sp = field.start_pose
        assert sim.pose() == pytest.approx((sp.x, sp.y, sp.theta), abs=1e-5)
        odom.clear()
        o = odom.wait(3, timeout=5)[-1].pose.pose.position
        assert math.hypot(o.x, o.y) < 0.01
        r = rospy.ServiceProxy("/sim/reset", ResetSimulation)(round=2)
        assert not r.success and "robot only" in r.message
        assert "SimTwo assumed" in (tmp_path / "bridge.log").read_text()
    finally:
        if sim is not None:
            sim.stop()
        stop_process(bridge)
