"""The in-process message path of composed nodes (``ros/mw/local.py``, ``raf compose``; issue 23).

Plain: the bus hands a message to every local subscription and to the middleware's publisher; a latched
topic's last message reaches a later subscription; a full queue drops the oldest and counts it; a closed
subscription hears nothing more (one its own callback closed still counts that delivery); a callback that
raises is reported and the next message still arrives; the ``wire`` copy is what local subscribers get, the
object itself what the middleware sends.

ROS 1 (a child process composing two components on a private master): a message between the components
arrives once (in-process, not also through rospy's socket to itself), a ``float32`` field arrives as the wire
makes it (32 bits), a publisher in another process still reaches the component through rospy, and rospy's
own clock (``use_sim_time``) still hears the ``/clock`` a component publishes; a recording component gets every
message once (``/clock`` too, the TF the components send, a latched topic told as latched). A node that fails
to start still leaves every plan closed (record's bag), a close that raises the others too.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from robotatfactory.ros.mw.base import Publisher, QoS
from robotatfactory.ros.mw.local import LocalBus


class _Inner(Publisher):
    def __init__(self):
        self.sent = []

    def publish(self, msg) -> None:
        self.sent.append(msg)

    def subscriber_count(self) -> int:
        return 0


def _until(pred, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return True
        time.sleep(0.005)
    return pred()


def test_the_bus_delivers_to_every_local_subscription_and_to_the_middleware():
    bus = LocalBus()
    inner = _Inner()
    pub = bus.publisher("/a", inner, QoS.RELIABLE)
    got1, got2, other = [], [], []
    s1 = bus.subscribe("/a", got1.append, 10)
    bus.subscribe("/a", got2.append, 10)
    bus.subscribe("/b", other.append, 10)
    for i in range(5):
        pub.publish(i)
    assert _until(lambda: len(got1) == 5 and len(got2) == 5)
    assert got1 == got2 == [0, 1, 2, 3, 4] and inner.sent == [0, 1, 2, 3, 4] and other == []
    assert pub.subscriber_count() == 2
    s1.close()
    pub.publish(5)
    assert _until(lambda: len(got2) == 6)
    time.sleep(0.05)
    assert got1 == [0, 1, 2, 3, 4], "a closed subscription still hears"
    assert pub.subscriber_count() == 1
    assert bus.counts() == {"delivered": 11, "dropped": 0}  # (closed subscriptions' included)
    s1.close()  # twice: counted once
    assert bus.counts() == {"delivered": 11, "dropped": 0}


def test_a_latched_topic_reaches_a_later_subscription_once_per_publisher():
    bus = LocalBus()
    p1, p2 = bus.publisher("/l", _Inner(), QoS.LATCHED), bus.publisher("/l", _Inner(), QoS.LATCHED)
    plain = bus.publisher("/p", _Inner(), QoS.RELIABLE)
    p1.publish("a1")
    p1.publish("a2")
    p2.publish("b1")
    plain.publish("x")
    late, late_plain = [], []
    bus.subscribe("/l", late.append, 10)
    bus.subscribe("/p", late_plain.append, 10)
    assert _until(lambda: len(late) == 2)
    time.sleep(0.05)
    assert sorted(late) == ["a2", "b1"] and late_plain == []


def test_a_full_queue_drops_the_oldest_and_counts_it():
    bus = LocalBus()
    pub = bus.publisher("/q", _Inner(), QoS.RELIABLE)
    handling, gate, got = threading.Event(), threading.Event(), []

    def slow(msg):
        handling.set()
        gate.wait(5.0)
        got.append(msg)

    bus.subscribe("/q", slow, 2)
    pub.publish(0)
    assert handling.wait(5.0)  # 0 is out of the queue, being handled
    for i in range(1, 6):
        pub.publish(i)  # the queue holds 2: 1, 2, 3 are dropped
    gate.set()
    assert _until(lambda: len(got) == 3)
    assert got == [0, 4, 5]
    assert bus.counts() == {"delivered": 3, "dropped": 3}


def test_a_subscription_closed_by_its_own_callback_counts_that_delivery():
    bus = LocalBus()
    pub = bus.publisher("/c", _Inner(), QoS.RELIABLE)
    got = []

    def once(msg):
        sub.close()
        got.append(msg)

    sub = bus.subscribe("/c", once, 10)
    pub.publish(1)
    assert _until(lambda: got == [1])
    pub.publish(2)
    time.sleep(0.05)
    assert got == [1] and bus.counts() == {"delivered": 1, "dropped": 0}


def test_a_callback_that_raises_is_reported_and_the_next_message_arrives():
    errors = []
    bus = LocalBus(on_error=errors.append)
    pub = bus.publisher("/e", _Inner(), QoS.RELIABLE)
    got = []

    def cb(msg):
        if msg == "bad":
            raise ValueError("no good")
        got.append(msg)

    bus.subscribe("/e", cb, 10)
    pub.publish("bad")
    pub.publish("good")
    assert _until(lambda: got == ["good"])
    assert len(errors) == 1 and "/e" in errors[0] and "ValueError: no good" in errors[0]


def test_a_closed_publisher_latches_no_more_and_the_bus_tells_a_latched_topic():
    bus = LocalBus()
    p = bus.publisher("/l", _Inner(), QoS.LATCHED)
    bus.publisher("/r", _Inner(), QoS.RELIABLE)
    p.publish("a")
    assert bus.latched("/l") and not bus.latched("/r") and not bus.latched("/none")
    bus.unpublish(p)
    late = []
    bus.subscribe("/l", late.append, 10)
    time.sleep(0.05)
    assert late == [] and not bus.latched("/l")


def test_local_subscribers_get_the_wire_copy_and_the_middleware_the_object():
    bus = LocalBus()
    inner = _Inner()
    pub = bus.publisher("/w", inner, QoS.LATCHED, wire=lambda m: round(m, 2))
    got = []
    bus.subscribe("/w", got.append, 10)
    pub.publish(1.23456)
    assert _until(lambda: got == [1.23])
    assert inner.sent == [1.23456]
    later = []
    bus.subscribe("/w", later.append, 10)  # the latched message as the wire made it
    assert _until(lambda: later == [1.23])


CHILD = textwrap.dedent("""
    import json, sys, time
    from robotatfactory.ros.mw import ros1
    from robotatfactory.ros.mw.base import QoS
    from robotatfactory.ros.mw.local import LocalBus
    from sensor_msgs.msg import LaserScan
    from std_msgs.msg import String
    import rosgraph, rospy
    from rosgraph_msgs.msg import Clock
    rosgraph.Master("/raf_local_test_cli").setParam("/use_sim_time", True)
    from geometry_msgs.msg import TransformStamped
    ros1._own_uri_out()
    bus = LocalBus()
    process = ros1.init_node("raf_local_test", argv=["x"], signals=False, bus=bus)  # as run_nodes makes it
    a, b = ros1.Ros1Node("comp_a", bus, tf=process), ros1.Ros1Node("comp_b", bus, tf=process)
    raw = {}  # a recorder component's raw subscriptions: topic -> [latched flags]
    for t in ("/tf", "/tf_static", "/clock", "/latched"):
        b.subscribe_raw(t, "", lambda data, info, t=t: raw.setdefault(t, []).append(info.latched))
    latched = a.publisher("/latched", String, QoS.LATCHED, 1)
    got = []
    b.subscribe("scan", LaserScan, lambda m: got.append(["scan", m.ranges[0], type(m.ranges).__name__]))
    b.subscribe("chat", String, lambda m: got.append(["chat", m.data]))
    scan, chat = a.publisher("scan", LaserScan), a.publisher("chat", String)
    clock = a.publisher("/clock", Clock)  # as the bridge publishes it: the process's own clock
    print("ready", flush=True)
    sys.stdin.readline()  # the parent's publisher is up and latched its message
    time.sleep(1.0)  # time for rospy to connect to it (and, were it not left out, to this process itself)
    scan.publish(LaserScan(ranges=[0.1]))
    chat.publish(String(data="inside"))
    latched.publish(String(data="l"))
    a.send_tf([TransformStamped(child_frame_id="x")])
    b.send_static_tf([TransformStamped(child_frame_id="y")])
    for i in range(20):
        clock.publish(Clock(clock=rospy.Time(12, 500000000)))
        time.sleep(0.05)
    time.sleep(0.5)
    print(json.dumps({"got": got, "names": [a.name, b.name], "private": a.resolve("~x"), "now": rospy.get_time(),
                      "raw": raw}), flush=True)
""")


OUTSIDE = textwrap.dedent("""
    import sys
    import rospy
    from std_msgs.msg import String
    rospy.init_node("raf_local_test_outside", disable_signals=True)
    rospy.Publisher("/chat", String, latch=True, queue_size=1).publish(String(data="outside"))
    print("ready", flush=True)
    sys.stdin.read()  # until the test closes it
""")


@pytest.mark.ros
def test_composed_components_hear_each_other_once_as_the_wire_gives_it_and_other_processes_too():
    from robotatfactory.ros.master import PrivateMaster

    # a master of its own: no other test's publishers (a latched /tf_static, a /clock) on the topics it counts
    with PrivateMaster() as master:
        env = master.env()
        outside = subprocess.Popen([sys.executable, "-c", OUTSIDE], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True, env=env)  # another process's publisher
        child = subprocess.Popen([sys.executable, "-c", CHILD], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, env=env)
        try:
            assert outside.stdout.readline().strip() == "ready", outside.stderr.read()[-2000:]
            assert child.stdout.readline().strip() == "ready", child.stderr.read()[-2000:]
            child.stdin.write("go\n")
            child.stdin.flush()
            out, err = child.communicate(timeout=60)
        finally:
            for p in (child, outside):
                if p.poll() is None:
                    p.kill()
                p.wait(10)
    assert child.returncode == 0, err[-2000:]
    res = json.loads(out.strip().splitlines()[-1])
    got = res["got"]
    assert sorted(m[1] for m in got if m[0] == "chat") == ["inside", "outside"], got  # each once
    scans = [m for m in got if m[0] == "scan"]
    assert len(scans) == 1, got
    assert scans[0][1] == pytest.approx(0.1, rel=1e-7) and scans[0][1] != 0.1  # float32, as over the wire
    assert scans[0][2] == "tuple"  # what rospy's deserialization makes of an array
    assert res["names"] == ["/comp_a", "/comp_b"] and res["private"] == "/comp_a/x"
    assert res["now"] == 12.5  # rospy's clock (use_sim_time) hears the process's own /clock
    raw = res["raw"]  # what a recorder among the components gets: each message once, TF included, latching told
    assert raw.get("/tf") == [False] and raw.get("/tf_static") == [True] and raw.get("/latched") == [True], raw
    assert len(raw.get("/clock", [])) == 20, raw.get("/clock")  # through rospy only: not twice


COMPOSE_FAILS = textwrap.dedent("""
    import argparse, json
    from robotatfactory.ros.cli import NodePlan
    from robotatfactory.ros.mw import ros1
    closed, stopped = [], []

    class Obj:
        def stop(self):
            stopped.append("a")

    def fails(node):
        raise RuntimeError("the recorder did not start")  # as a recorder whose start raised after its bag opened

    def close_fails():
        closed.append("b")
        raise OSError("the bag is gone")

    plans = [NodePlan("a", "comp_a", {}, lambda n: Obj(), lambda o: "a running", close=lambda: closed.append("a")),
             NodePlan("b", "comp_b", {}, fails, lambda o: "", close=close_fails),
             NodePlan("c", "comp_c", {}, fails, lambda o: "", close=lambda: closed.append("c"))]
    try:
        ros1.run_nodes(argparse.Namespace(ns="", name="raf_compose_test", no_sim_time=True, roscore=False), plans)
    except RuntimeError as e:
        print(json.dumps({"error": str(e), "closed": closed, "stopped": stopped}), flush=True)
""")


@pytest.mark.ros
def test_raf_compose_closes_every_plan_when_a_node_fails_to_start_and_one_close_fails():
    from robotatfactory.ros.master import PrivateMaster

    with PrivateMaster() as master:
        r = subprocess.run([sys.executable, "-c", COMPOSE_FAILS], capture_output=True, text=True, timeout=60,
                           env=master.env())
    assert r.returncode == 0, r.stderr[-2000:]
    res = json.loads(r.stdout.strip().splitlines()[-1])
    assert res == {"error": "the recorder did not start", "stopped": ["a"], "closed": ["c", "b", "a"]}, res
    assert "raf compose: closing b failed: OSError: the bag is gone" in r.stderr, r.stderr[-2000:]


def test_a_plan_run_alone_is_closed_whatever_its_node_did(monkeypatch):
    from robotatfactory.ros import cli

    def fails(*a):
        raise RuntimeError("no master")

    closed = []
    monkeypatch.setattr(cli, "run_node", fails)
    plan = cli.NodePlan("record", "raf_record", {}, lambda n: None, lambda o: "", close=lambda: closed.append(1))
    with pytest.raises(RuntimeError):
        plan.run(None)
    monkeypatch.setattr(cli, "run_node", lambda *a: 0)
    assert plan.run(None) == 0 and closed == [1, 1]


@pytest.mark.parametrize("nodes, error", [
    ([], "no node given"),
    (["--", "sim"], "'sim' cannot be composed"),
    (["--", "bridge", "--ns", "robot2"], "share the process's namespace"),
    (["--", "agent", "--", "agent"], "two nodes named 'raf_agent'"),
    (["--", "agent", "--set", "no_such_setting=1"], "no_such_setting"),
])
def test_raf_compose_refuses_a_bad_command_line_with_a_clear_error(raf_cmd, nodes, error):
    r = subprocess.run([*raf_cmd, "compose", *nodes], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stdout + r.stderr
    assert error in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_compose_splits_the_command_lines_at_each_double_dash():
    from robotatfactory.commands.compose import split

    assert split(["--", "bridge", "--port", "1", "--", "--", "agent", "--set", "a=1"]) == [
        ["bridge", "--port", "1"], ["agent", "--set", "a=1"]]


def test_raf_compose_on_ros2_says_it_is_ros1_only():
    from robotatfactory.ros.processes import interpreter

    py = interpreter("ros2")
    assert py is not None, "no ROS 2 environment (scripts/bootstrap.sh builds .venv-ros2)"
    r = subprocess.run([str(py), "-m", "robotatfactory", "compose", "--", "agent"], capture_output=True, text=True,
                       timeout=120, env={**os.environ, "RAF_MIDDLEWARE": "ros2"})
    assert r.returncode == 2, r.stdout + r.stderr
    assert "not on ros2 (ROS 1 only)" in r.stderr, r.stderr
