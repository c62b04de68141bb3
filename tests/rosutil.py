"""ROS helpers for tests: a real roscore on a free port (never 11311), one in-process test node, waiting.

rospy allows ``init_node`` once per process and binds it to the master it was given, so a pytest process
shares ONE roscore among all test files that use ROS in-process: use the session fixture ``ros_master``
(import it into a test module: ``from rosutil import ros_master  # noqa: F401``) and ``test_node()``.
Child processes (``raf bridge``, ``roslaunch``, ``rosbag``) get ``master.env()``.

    def test_x(ros_master):
        test_node()
        odom = Collector("/odom", Odometry)
        odom.wait(5, timeout=10)
"""
from __future__ import annotations

import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
from robotatfactory.ros.master import PrivateMaster, free_port, stop_process  # noqa: E402,F401


class RosMaster(PrivateMaster):
    """``roscore -p PORT`` on a free port (see :class:`robotatfactory.ros.master.PrivateMaster`)."""


_MASTER: RosMaster | None = None
_NODE_LOCK = threading.Lock()
_NODE_STARTED = False


def master() -> RosMaster:
    """The process-wide test roscore (started on first use, stopped at exit)."""
    global _MASTER
    if _MASTER is None:
        _MASTER = RosMaster().start()
        _MASTER.use_in_this_process()
        import atexit

        atexit.register(_MASTER.cleanup)
    return _MASTER


@pytest.fixture(scope="session")
def ros_master():
    m = master()
    yield m


def test_node(name: str = "raf_test"):
    """Init the in-process rospy node (once per process) against :func:`master`."""
    global _NODE_STARTED
    import rospy

    master()
    with _NODE_LOCK:
        if not _NODE_STARTED:
            rospy.init_node(name, anonymous=True, disable_signals=True)
            _NODE_STARTED = True
    return rospy


test_node.__test__ = False  # not a pytest test


def raf_process(args: list[str], env: dict, log: Path | None = None) -> subprocess.Popen:
    """``raf ARGS`` with this interpreter, in its own process group, output to ``log`` (or discarded)."""
    out = open(log, "wb") if log else subprocess.DEVNULL
    return subprocess.Popen([sys.executable, "-m", "robotatfactory", *args], env=env, stdout=out,
                            stderr=subprocess.STDOUT, start_new_session=True, cwd=str(ROOT))


class Collector:
    """Subscribes to a topic and keeps every message with its receive time (wall, monotonic)."""

    def __init__(self, topic: str, msg_type, maxlen: int = 100000):
        import rospy

        self.msgs: list = []
        self.times: list[float] = []
        self.maxlen = maxlen
        self._lock = threading.Lock()
        self.sub = rospy.Subscriber(topic, msg_type, self._cb, queue_size=100, tcp_nodelay=True)

    def _cb(self, m):
        with self._lock:
            if len(self.msgs) < self.maxlen:
                self.msgs.append(m)
                self.times.append(time.monotonic())

    def wait(self, n: int = 1, timeout: float = 10.0, pred=None) -> list:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                got = [m for m in self.msgs if pred is None or pred(m)]
            if len(got) >= n:
                return got
            time.sleep(0.02)
        raise TimeoutError(f"{self.sub.name}: {len(got)} of {n} messages within {timeout} s")

    def clear(self):
        with self._lock:
            self.msgs.clear()
            self.times.clear()

    def close(self):
        self.sub.unregister()


def wait_until(pred, timeout: float = 10.0, interval: float = 0.02, what: str = "condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    raise TimeoutError(f"{what} not met within {timeout} s")
