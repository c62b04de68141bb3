"""The node layer's handles and services on each middleware (``[ros1]``: a private roscore; ``[ros2]``: a
private domain id), on rosutil's test node in this process:

* ``Node.close(handle)`` ends a subscription, publisher, service or timer (twice, ``None``: nothing happens);
* ``Bridge.stop()`` leaves the graph: the ``sim/*`` services and the command subscriptions are gone;
* a ``sim/*`` call that waits for a slow simulator does not hold up ``cmd_vel``: the commands still reach the
  bridge's replies to the simulator while the call is pending (ROS 2's one-threaded executor answered the
  call in the callback before: cmd_vel waited for it);
* ROS 2: a service waits 3 s (data/fastdds.xml) for a new client's response reader before it drops the answer;
* a whole number given where a parameter's default is a real becomes a real (ROS 2 types parameters
  strictly): overrides, parameter files and the nodes' ``given`` settings, the rule in one place.
"""
from __future__ import annotations

import json
import socket
import subprocess
import sys
import textwrap
import threading
import time

import pytest

from rosutil import (ROOT, Collector, call_service, free_port, middleware, publisher, ros_graph,  # noqa: F401
                     service_names, srv_types, test_node, unpublish, wait_for_service, wait_until)

pytestmark = [pytest.mark.ros, pytest.mark.middlewares]


def _graph(topic: str) -> tuple[int, int]:
    """(publishers, subscribers) of ``topic`` as the graph lists them (ROS 1: the master's system state)."""
    node = test_node()
    name = node.resolve(topic)
    if middleware() == "ros2":
        return node.node.count_publishers(name), node.node.count_subscribers(name)
    import rosgraph

    pubs, subs, _ = rosgraph.Master("/raf_test_graph").getSystemState()
    return (sum(len(n) for t, n in pubs if t == name), sum(len(n) for t, n in subs if t == name))


def _served(name: str) -> bool:
    """Whether a server offers the service ``name`` (ROS 2: counted servers; the graph's service list also
    names a service that only a client asks for, e.g. this test's own client)."""
    if middleware() == "ros2":
        return test_node().node.count_services(name) > 0
    return name in service_names()


def test_close_ends_subscription_publisher_service_and_timer(middleware, ros_graph):
    from std_msgs.msg import String

    node = test_node()
    # a subscription: closed, it hears nothing more and the publisher loses it
    pub = node.publisher("/raf_close_test/a", String, depth=10)
    col = Collector("/raf_close_test/a", String)
    wait_until(lambda: pub.subscriber_count() > 0, 10, what="the subscription")
    wait_until(lambda: (pub.publish(String(data="x")), len(col.msgs) > 0)[1], 10, what="a message")
    node.close(col.sub)
    node.close(col.sub)  # twice: nothing
    wait_until(lambda: _graph("/raf_close_test/a")[1] == 0, 10, what="the subscription to leave the graph")
    n = len(col.msgs)
    for _ in range(5):
        pub.publish(String(data="after"))
        time.sleep(0.05)
    time.sleep(0.3)
    assert len(col.msgs) == n and not any(m.data == "after" for m in col.msgs)

    # a publisher: closed, the subscriber sees no publisher
    pub2 = node.publisher("/raf_close_test/b", String, depth=10)
    col2 = Collector("/raf_close_test/b", String)
    wait_until(lambda: col2.publishers() > 0, 10, what="the publisher")
    node.close(pub2)
    node.close(pub2)
    wait_until(lambda: _graph("/raf_close_test/b")[0] == 0, 10, what="the publisher to leave the graph")
    node.close(col2.sub)

    # a timer: closed, it fires no more
    ticks = []
    t = node.timer(0.02, lambda: ticks.append(time.monotonic()))
    wait_until(lambda: len(ticks) >= 3, 10, what="the timer")
    node.close(t)
    time.sleep(0.1)  # a tick already under way may still land
    n = len(ticks)
    time.sleep(0.4)
    assert len(ticks) == n
    node.close(t)

    # a service: closed, it leaves the graph
    Trigger = srv_types().Trigger
    srv = node.service("/raf_close_test/srv", Trigger, lambda req, resp: (setattr(resp, "success", True), resp)[1])
    wait_for_service("/raf_close_test/srv", Trigger, 10)
    assert call_service("/raf_close_test/srv", Trigger, 10).success is True
    node.close(srv)
    node.close(srv)
    wait_until(lambda: not _served("/raf_close_test/srv"), 10, what="the service to leave the graph")

    node.close(None)
    with pytest.raises(TypeError):
        node.close("not a handle")
    unpublish(pub)


class SlowControl:
    """A stand-in's control channel that answers ``get_state`` at once and ``step`` after ``delay`` s."""

    def __init__(self, delay: float):
        self.delay = delay
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.1)
        self.port = self.sock.getsockname()[1]
        self.step_asked = threading.Event()
        self.step_answered_at: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(65535)
            except (socket.timeout, OSError):
                continue
            req = json.loads(data)
            if req.get("op") == "step":
                self.step_asked.set()
                threading.Thread(target=self._answer_step, args=(req, addr), daemon=True).start()
            else:
                self._send({"ok": True, "id": req["id"], "paused": True, "time": 0.0, "seq": 0,
                            "pose": [0.0, 0.0, 0.0]}, addr)

    def _answer_step(self, req, addr) -> None:
        time.sleep(self.delay)
        self.step_answered_at = time.monotonic()
        self._send({"ok": True, "id": req["id"], "seq": 1, "time": 0.04}, addr)

    def _send(self, reply: dict, addr) -> None:
        try:
            self.sock.sendto(json.dumps(reply).encode(), addr)
        except OSError:
            pass

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.sock.close()


def test_bridge_stop_leaves_the_graph_and_a_slow_sim_call_does_not_hold_up_cmd_vel(middleware, ros_graph, field):
    from fakesim import FakeSim
    from geometry_msgs.msg import Twist

    from robotatfactory.ros.bridge_node import Bridge
    from robotatfactory.ros.config import load_config

    node = test_node()
    ctl = SlowControl(delay=3.0)
    port = free_port(socket.SOCK_DGRAM)
    bridge = Bridge(load_config({"udp": {"port": port}, "camera": {"enabled": False},
                                 "simulator": {"control": f"127.0.0.1:{ctl.port}"},
                                 "watchdog": {"timeout": 2.0}}), node, field=field).start()
    sim = FakeSim(("127.0.0.1", port), None, lockstep=False, realtime=True).start()
    pub = None
    try:
        wait_until(lambda: len(sim.received) > 5, 15, what="the bridge's replies")
        wait_for_service("/sim/step", srv_types().StepSimulation, 15)
        pub = publisher("cmd_vel", Twist, wait_for=10)
        result: list = []
        caller = threading.Thread(target=lambda: result.append(
            call_service("/sim/step", srv_types().StepSimulation, 20, steps=1)), daemon=True)
        caller.start()
        assert ctl.step_asked.wait(10), "the step request reached the simulator"
        seen = None
        tw = Twist()
        tw.linear.x = 0.3
        end = time.monotonic() + 10
        while seen is None and time.monotonic() < end and ctl.step_answered_at is None:
            pub.publish(tw)
            time.sleep(0.04)
            with sim._lock:
                seen = next((r.t_wall for r in sim.received if abs(r.v - 0.3) < 1e-6), None)
        answered = ctl.step_answered_at
        assert seen is not None and (answered is None or seen < answered), \
            "cmd_vel reached the replies to the simulator only after the slow sim/step call was answered"
        caller.join(15)
        assert result and result[0].success, result
        # Bridge.stop(): the sim/* services and the command subscriptions leave the graph
        names = [f"/sim/{s}" for s in ("reset", "pause", "resume", "step", "set_robot_pose", "place_part",
                                       "get_state")]
        assert all(_served(n) for n in names)
        bridge.stop()
        wait_until(lambda: not any(_served(n) for n in names), 15, what="the sim/* services to leave the graph")
        wait_until(lambda: _graph("cmd_vel")[1] == 0, 15, what="cmd_vel's subscription to leave the graph")
        bridge.stop()  # twice: nothing
    finally:
        bridge.stop()
        sim.stop()
        ctl.close()
        if pub is not None:
            unpublish(pub)


# ---- whole numbers for reals (ROS 2 types parameters strictly) ------------------------------------------

def test_typed_like_and_typed_tree():
    from robotatfactory.ros.mw.base import typed_like, typed_tree

    assert typed_like(3, 1.5) == 3.0 and type(typed_like(3, 1.5)) is float
    assert type(typed_like(3, 2)) is int and typed_like(True, 1.0) is True and typed_like("3", 1.0) == "3"
    assert [type(v) for v in typed_like([1, 2], [0.5, 0.5])] == [float, float]
    assert [type(v) for v in typed_like([1, 2], [1, 2])] == [int, int]
    t = typed_tree({"ekf": {"history_s": 3, "extra": 4}, "new": 5, "name": "x"}, {"ekf": {"history_s": 1.0}})
    assert t == {"ekf": {"history_s": 3.0, "extra": 4}, "new": 5, "name": "x"}
    assert type(t["ekf"]["history_s"]) is float and type(t["ekf"]["extra"]) is int and type(t["new"]) is int


ROS2_PARAMS = textwrap.dedent("""
    import json, sys
    from robotatfactory.ros.mw import ros2
    from rclpy.parameter import Parameter
    out = {}
    # overrides (what raf bridge hands the node) and a parameter file, both with whole numbers for reals
    n = ros2.init_node("raf_bridge", argv=["x", "--ros-args", "--params-file", sys.argv[1]],
                       params={"watchdog": {"timeout": 1}, "udp": {"port": 9811}})
    from robotatfactory.ros.config import default_params, describe_param, load_config
    got = n.params(default_params(), describe_param)
    cfg = load_config(got)
    p = n.node.get_parameter("watchdog.timeout")
    out["bridge"] = [got["watchdog"]["timeout"], type(got["watchdog"]["timeout"]).__name__,
                     p.type_ == Parameter.Type.DOUBLE, got["stream"]["takeover_after"],
                     type(got["stream"]["takeover_after"]).__name__, got["udp"]["port"],
                     type(got["udp"]["port"]).__name__]
    # a setting unset by default (the robot file's) is declared with dynamic typing: the settings make it a real
    out["bridge_unset"] = [got["camera"]["fx"], cfg.robot.camera.fx, type(cfg.robot.camera.fx).__name__]
    n.destroy()
    # the agent's and the localization's given settings
    from robotatfactory.ros.agent_node import node_params as agent_params
    n = ros2.init_node("raf_agent", params={"max_input_age": 2})
    got = agent_params(n, {"max_input_age": 2, "command_latency": 0})
    out["agent"] = [got["max_input_age"], type(got["max_input_age"]).__name__,
                    type(got["command_latency"]).__name__,
                    n.node.get_parameter("max_input_age").type_ == Parameter.Type.DOUBLE]
    n.destroy()
    from robotatfactory.ros.localization_node import node_params as loc_params
    settings = {"ekf": {"history_s": 3}, "node": {"log_period": 7}}
    n = ros2.init_node("raf_localization", params=settings)
    got = loc_params(n, settings)
    out["localization"] = [got["ekf"]["history_s"], type(got["ekf"]["history_s"]).__name__,
                           got["node"]["log_period"], type(got["node"]["log_period"]).__name__]
    n.destroy()
    import rclpy
    rclpy.try_shutdown()
    print(json.dumps(out))
""")


def test_whole_numbers_given_for_reals_become_reals_on_ros2(tmp_path):
    """On rclpy (the ROS 2 interpreter, in a subprocess on a private domain): an override, a parameter file
    and the agent's / localization's given settings with ``1`` where the default is a real are declared as
    reals with that value; an integer parameter stays an integer."""
    import importlib.util

    from robotatfactory.ros.master import PrivateDomain

    py = sys.executable if importlib.util.find_spec("rclpy") else str(ROOT / ".venv-ros2" / "bin" / "python")
    f = tmp_path / "p.yaml"
    f.write_text("/**/raf_bridge:\n  ros__parameters:\n    stream:\n      takeover_after: 3\n"
                 "    camera:\n      fx: 283\n")
    with PrivateDomain() as dom:
        r = subprocess.run([py, "-c", ROS2_PARAMS, str(f)], env=dom.env(), cwd=ROOT, capture_output=True,
                           text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-3000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out["bridge"] == [1.0, "float", True, 3.0, "float", 9811, "int"]
    assert out["bridge_unset"] == [283, 283.0, "float"]
    assert out["agent"] == [2.0, "float", "float", True]
    assert out["localization"] == [3.0, "float", 7.0, "float"]


ROS2_LATE_READER_SERVER = textwrap.dedent("""
    import json, sys, threading, time, warnings
    from robotatfactory.ros.mw import ros2
    from std_srvs.srv import Trigger

    asked, out = [], []
    def show(message, category, filename, lineno, file=None, line=None):
        if "failed to send response" not in str(message) or not asked:
            return
        out.append(str(message))
        print(json.dumps({"waited_s": time.monotonic() - asked[0], "warning": str(message)}), flush=True)
    warnings.showwarning = show
    warnings.filterwarnings("always", message="failed to send response")
    node = ros2.init_node("raf_late_reader", signals=False)
    def answer(req, resp):
        asked.append(time.monotonic())
        resp.success = True
        return resp
    node.service("late_reader", Trigger, answer)
    spinner = node.spin_in_background("spin")
    print("ready", flush=True)
    t = time.monotonic()
    while not out and time.monotonic() - t < 30:
        time.sleep(0.05)
    node.finish("done", spinner)
""")

ROS2_LATE_READER_CLIENT = textwrap.dedent("""
    import rclpy
    from std_srvs.srv import Trigger
    rclpy.init()
    node = rclpy.create_node("raf_late_reader_client")
    cli = node.create_client(Trigger, "/late_reader")
    cli.wait_for_service(timeout_sec=3.0)  # False (its reader never matches), but the request side has matched
    fut = cli.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(node, fut, timeout_sec=6.0)
    print("answered" if fut.done() else "unanswered", flush=True)
""")

# a client whose response reader never matches the service's response writer (another partition): to the
# service it is a client whose reader has not been discovered yet, for as long as the service waits
NEVER_MATCHING_READER = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <data_reader profile_name="client"><qos><partition><names><name>elsewhere</name></names></partition></qos>
  </data_reader>
</profiles>
"""


def test_a_ros2_service_waits_seconds_for_a_new_clients_reader(tmp_path):
    """ROS 2 (Fast DDS): a service answers a client only once its response writer has matched the client's
    response reader; data/fastdds.xml's "service" profile lets it wait 3 s for that instead of Fast DDS's
    100 ms, after which the answer is dropped (a new client's first call on a busy machine went unanswered:
    CI, /reset_simulation). Provoked with a client whose reader never matches: the service (the node layer's,
    answering in a worker) gives up after about 3 s, not 0.1 s."""
    import importlib.util

    from robotatfactory.ros.master import PrivateDomain

    py = sys.executable if importlib.util.find_spec("rclpy") else str(ROOT / ".venv-ros2" / "bin" / "python")
    profile = tmp_path / "client.xml"
    profile.write_text(NEVER_MATCHING_READER)
    with PrivateDomain() as dom:
        env = dom.env()
        env.pop("FASTRTPS_DEFAULT_PROFILES_FILE", None)
        env.pop("FASTDDS_DEFAULT_PROFILES_FILE", None)
        server = subprocess.Popen([py, "-c", ROS2_LATE_READER_SERVER], env=env, cwd=ROOT, text=True,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        try:
            assert server.stdout.readline().strip() == "ready", server.stderr.read()[-3000:]
            client = subprocess.run([py, "-c", ROS2_LATE_READER_CLIENT], cwd=ROOT, capture_output=True, text=True,
                                    timeout=60, env=dict(env, FASTRTPS_DEFAULT_PROFILES_FILE=str(profile)))
            out, err = server.communicate(timeout=60)
        finally:
            server.kill()
    assert client.stdout.strip() == "unanswered", client.stderr[-3000:]
    got = json.loads(out.strip().splitlines()[-1])
    assert "client will not receive response" in got["warning"], got
    assert 2.5 < got["waited_s"] < 4.5, got
