"""The pacer over a middleware (ros/pace.py), on a recording stand-in for a node: each node paces on its own
topic and hears only the nodes it takes inputs from; the bridge's wait forgets the cycles it has answered."""
from robotatfactory.pace import Pace
from robotatfactory.ros.pace import READY, TOPIC, Pacer, to_msg


class _Pub:
    def __init__(self, topic, sent):
        self.topic, self.sent = topic, sent

    def publish(self, m):
        self.sent.append((self.topic, m))


class FakeNode:
    def __init__(self):
        self.sent, self.subs, self.warnings = [], {}, []

    def publisher(self, topic, *a):
        return _Pub(topic, self.sent)

    def subscribe(self, topic, _type, cb, *a):
        self.subs[topic] = cb

    def warn(self, text, **kw):
        self.warnings.append(text)

    def ok(self):
        return True


def test_each_node_paces_on_its_own_topic_and_hears_only_its_inputs():
    node = FakeNode()
    p = Pacer(node, "agent", {"bridge": ("odom",), "localization": ("pose",)})
    try:
        assert set(node.subs) == {f"{TOPIC}/bridge", f"{TOPIC}/localization", TOPIC}
        assert [t for t, _ in node.sent] == [f"{TOPIC}/agent"]  # its hello; not ready: nothing heard yet
        node.subs[f"{TOPIC}/bridge"](to_msg(Pace("bridge", -1.0)))
        assert len(node.sent) == 1
        node.subs[f"{TOPIC}/localization"](to_msg(Pace("localization", 0.04, {"pose": 0})))  # joined late
        assert node.sent[-1][0] == TOPIC and node.sent[-1][1].status[0].message == "ready"
        p.sent("cmd_vel")
        p.done(0.04)
        assert node.sent[-1][0] == f"{TOPIC}/agent"
    finally:
        p.close()


def test_the_bridge_waits_for_the_ready_of_the_whole_loop():
    node = FakeNode()
    p = Pacer(node, "bridge", {"agent": ("cmd_vel",)}, timeout=0.05)
    for name in ("camera", "agent"):
        node.subs[TOPIC](to_msg(Pace(name, READY)))
    assert p.wait_ready(("camera", "agent"), timeout=0.5) is True
    assert p.wait_ready(("camera", "localization"), timeout=0.05) is False and node.warnings


def test_the_bridge_forgets_the_cycles_it_has_answered():
    node = FakeNode()
    p = Pacer(node, "bridge", {"agent": ("cmd_vel",)}, timeout=0.05)
    on_pace = node.subs[f"{TOPIC}/agent"]
    for k in range(1, 201):
        t = 0.04 * k
        on_pace(to_msg(Pace("agent", t, {"cmd_vel": k})))
        p.got("cmd_vel")
        assert p.wait(t) is True
    assert p.book.backlog() == 0  # (kept, 200 paces would be searched at every message)
    on_pace(to_msg(Pace("agent", 0.04 * 201, {"cmd_vel": 202})))  # one command lost on the way
    assert p.wait(0.04 * 201) is False and p.book.timeouts == 1 and p.book.backlog() == 0
