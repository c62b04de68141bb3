"""The pacing bookkeeping (robotatfactory/pace.py): a cycle runs once every upstream node has paced it and the
messages it counted are in, whatever order they came in; a lost message costs one timeout, then the counts
agree again."""
import threading

import pytest

from robotatfactory.pace import Pace, PaceBook, PaceCounts

NEEDS = {"bridge": ("odom", "scan"), "camera": ("image",)}


def test_a_cycle_waits_for_every_pace_and_every_counted_message():
    b = PaceBook(NEEDS)
    assert b.next_ready() is None and b.pending() is None
    b.paced(Pace("bridge", 0.04, {"odom": 1, "scan": 0, "contact": 1}))
    assert b.pending() == 0.04 and b.next_ready() is None  # the camera has not paced it
    b.paced(Pace("camera", 0.04, {"image": 1}))
    assert b.next_ready() is None and "odom 0/1" in b.missing(0.04) and "image 0/1" in b.missing(0.04)
    b.got("image")
    assert b.next_ready() is None  # the odom is still on its way (a pace may overtake it)
    b.got("odom")
    assert b.next_ready() == 0.04  # "contact" is not among what this node takes: not waited for
    b.done(0.04)
    assert b.next_ready() is None and b.pending() is None


def test_cycles_run_in_order_and_paces_of_other_nodes_are_ignored():
    b = PaceBook(NEEDS)
    for t, n in ((0.04, 1), (0.08, 2)):
        b.paced(Pace("bridge", t, {"odom": n}))
        b.paced(Pace("camera", t, {"image": 0}))
        b.paced(Pace("agent", t, {"cmd_vel": n}))
    b.got("odom", 2)
    assert b.next_ready() == 0.04
    b.done(0.04)
    assert b.next_ready() == 0.08
    b.paced(Pace("bridge", float("nan"), {}))  # garbage: ignored
    b.done(0.08)
    assert b.pending() is None


def test_wait_blocks_until_the_inputs_come_and_times_out_otherwise():
    b = PaceBook({"agent": ("cmd_vel",)})
    b.paced(Pace("agent", 1.0, {"cmd_vel": 3}))
    b.got("cmd_vel", 2)
    threading.Timer(0.05, b.got, args=("cmd_vel",)).start()
    assert b.wait(1.0, timeout=5.0) is True
    b.paced(Pace("agent", 1.04, {"cmd_vel": 5}))  # one message lost on the way
    assert b.wait(1.04, timeout=0.05) is False and b.timeouts == 1
    b.give_up(1.04)  # taken as complete: the counts agree again from here
    b.done(1.04)
    b.paced(Pace("agent", 1.08, {"cmd_vel": 6}))
    b.got("cmd_vel")
    assert b.wait(1.08, timeout=0.5) is True


def test_wait_done_blocks_until_another_thread_has_run_the_cycle():
    b = PaceBook({"agent": ("cmd_vel",)})
    b.paced(Pace("agent", 1.0, {"cmd_vel": 0}))
    assert b.wait_done(1.0, timeout=0.05) is False  # nobody ran it
    threading.Timer(0.05, b.done, args=(1.0,)).start()
    assert b.wait_done(1.0, timeout=5.0) is True
    assert b.pending() is None and b.wait_done(1.0, timeout=0.0) is True


def test_a_node_behind_in_the_loop_is_waited_for_one_cycle_late():
    """The localization takes the agent's electromagnet command, which the agent sends after the
    localization's cycle: cycle k needs the agent's pace of cycle k - 1 (none for the first cycle)."""
    b = PaceBook({"bridge": ("odom",)}, behind={"agent": ("electromagnet",)})
    b.paced(Pace("bridge", 0.04, {"odom": 1}))
    b.got("odom")
    assert b.next_ready() == 0.04  # the first cycle: nothing before it
    b.done(0.04)
    b.paced(Pace("bridge", 0.08, {"odom": 2}))
    b.got("odom")
    assert b.next_ready() is None and "agent's pace of 0.040 s" in b.missing(0.08)
    b.paced(Pace("agent", 0.04, {"electromagnet": 1}))
    assert b.next_ready() is None  # the command itself is still on its way
    b.got("electromagnet")
    assert b.next_ready() == 0.08
    b.done(0.08)
    b.paced(Pace("agent", 0.08, {"electromagnet": 2}))  # kept for the next cycle
    b.paced(Pace("bridge", 0.12, {"odom": 3}))
    b.got("odom")
    b.got("electromagnet")
    b.got("electromagnet")  # the agent's next command, already here: not this cycle's
    assert b.next_ready() == 0.12
    assert b.required(0.12) == {"odom": 3, "electromagnet": 2}  # what the cycle takes of each input


def test_counts_are_the_messages_sent_so_far():
    c = PaceCounts("bridge")
    c.sent("odom")
    c.sent("scan", 2)
    p = c.pace(0.12)
    c.sent("odom")
    assert (p.name, p.t, p.counts) == ("bridge", 0.12, {"odom": 1, "scan": 2})  # a snapshot
    with pytest.raises(ValueError):
        PaceBook({})
