"""``raf up`` on the middleware this interpreter has: the set comes up, odometry arrives on /odom (seen by a
listener in another process, on the same private graph), Ctrl-C stops every process it started (their
children too: the bridge's camera process); a child that dies ends ``raf up`` with exit code 1 and its log."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from robotatfactory.ros.master import private_graph, stop_process

ROOT = Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.middlewares]

LISTENER = textwrap.dedent("""
    import sys, threading, time
    from nav_msgs.msg import Odometry
    from robotatfactory.ros.mw import QoS, api
    m = api()
    node = m.init_node("raf_test_odom", anonymous=True, signals=False)
    got = []
    node.subscribe("/odom", Odometry, lambda msg: got.append(msg.pose.pose.position.x), QoS.RELIABLE)
    spinner = None
    if m.NAME == "ros2":
        spinner = threading.Thread(target=node.spin, daemon=True)
        spinner.start()
    end = time.monotonic() + float(sys.argv[1])
    while time.monotonic() < end and len(got) < int(sys.argv[2]):
        time.sleep(0.05)
    print(len(got), flush=True)
    node.shutdown("done")
    if spinner is not None:
        spinner.join(5)
        node.destroy()
        import rclpy
        rclpy.try_shutdown()
""")


def _graph_env(graph) -> dict:
    env = graph.env()
    env.pop("ROS_NAMESPACE", None)
    return env


def _start_up(env: dict, log_dir: Path, *extra: str) -> tuple[subprocess.Popen, list[str]]:
    """``raf up`` (free ports) until it says it runs; returns the process and its output so far."""
    p = subprocess.Popen([sys.executable, "-m", "robotatfactory", "up", "--free-ports", "--log-dir", str(log_dir),
                          *extra], env=env, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True)
    lines: list[str] = []
    end = time.monotonic() + 120
    while time.monotonic() < end:
        line = p.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip())
        if "raf up: running" in line:
            return p, lines
    stop_process(p, signal.SIGKILL)
    raise AssertionError("raf up did not come up:\n" + "\n".join(lines))


def _pids(lines: list[str]) -> dict[str, int]:
    return {m.group(1): int(m.group(2)) for m in (re.match(r"\s+(\w+)\s+pid (\d+)", ln) for ln in lines) if m}


def _session_members(sids) -> list[int]:
    """Processes whose session is one of ``sids`` (each child of raf up leads a session of its own)."""
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) in sids and fields[0] != "Z":  # fields[3]: session id
            out.append(int(d.name))
    return out


@pytest.fixture
def graph(middleware):
    """A private graph of this interpreter's middleware (conftest's ``middleware``: ros1 in .venv, ros2 in
    .venv-ros2), which ``raf up`` joins (ROS_MASTER_URI / ROS_DOMAIN_ID in its environment)."""
    g = private_graph(middleware)
    g.start()
    try:
        yield g
    finally:
        g.cleanup()


def test_up_brings_up_odometry_and_ctrl_c_stops_everything(graph, tmp_path):
    env = _graph_env(graph)
    p, lines = _start_up(env, tmp_path / "logs")
    try:
        pids = _pids(lines)
        assert set(pids) == {"bridge", "localize", "sim"}, lines
        assert all(_session_members({pid}) for pid in pids.values()), "every child runs"
        r = subprocess.run([sys.executable, "-c", LISTENER, "30", "10"], env=env, cwd=ROOT, capture_output=True,
                           text=True, timeout=90)
        assert r.returncode == 0, r.stderr[-2000:]
        assert int(r.stdout.split()[-1]) >= 10, f"odometry on /odom: {r.stdout} {r.stderr[-1500:]}"
        os.killpg(p.pid, signal.SIGINT)  # what Ctrl-C in its terminal does
        rest, _ = p.communicate(timeout=30)
    finally:
        stop_process(p, signal.SIGKILL)
    assert p.returncode == 0, rest
    assert "stopping everything" in rest and "still running" not in rest, rest
    left = _session_members(set(pids.values()))
    assert not left, f"processes left after Ctrl-C: {left}"
    assert (tmp_path / "logs" / "bridge.log").read_text(), "each child logs to a file"


def test_a_child_that_dies_ends_up_with_its_log(graph, tmp_path):
    env = _graph_env(graph)
    p, lines = _start_up(env, tmp_path / "logs", "--no-localize")
    try:
        pids = _pids(lines)
        assert set(pids) == {"bridge", "sim"}, lines
        os.kill(pids["bridge"], signal.SIGKILL)
        rest, _ = p.communicate(timeout=30)
    finally:
        stop_process(p, signal.SIGKILL)
    assert p.returncode == 1, rest
    assert "bridge exited with code -9" in rest, rest
    assert "listening on udp" in rest, "the dead child's last log lines are printed"
    assert not _session_members(set(pids.values())), "the other children are stopped"
