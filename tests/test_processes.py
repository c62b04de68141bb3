"""ros/processes.py: the one helper that starts, watches and stops the raf processes of a benchmark or an
experiment (no ROS needed for these)."""
import os
import sys
import time

import pytest

from robotatfactory.ros.processes import Procs, interpreter, raf_cmd, wait_until


def test_a_process_that_dies_is_reported_with_its_log(tmp_path):
    with Procs(tmp_path) as procs:
        procs.start("short", [sys.executable, "-c", "print('bye from short'); raise SystemExit(3)"], dict(os.environ))
        procs.start("long", [sys.executable, "-c", "import time; time.sleep(60)"], dict(os.environ))
        with pytest.raises(RuntimeError, match=r"short exited early with code 3:\nbye from short"):
            wait_until(lambda: False, 20, "nothing", check=procs.check)
        long_ = procs.get("long")
        assert long_.poll() is None
    assert long_.poll() is not None  # stopped with the context (its whole session)
    assert (tmp_path / "short.log").read_text().strip() == "bye from short"


def test_an_expected_exit_is_waited_for_not_reported(tmp_path):
    with Procs(tmp_path) as procs:
        procs.start("tool", [sys.executable, "-c", "import sys; sys.exit(0)"], dict(os.environ), may_exit=True)
        assert procs.wait("tool", 20) == 0
        procs.check()  # no error
        procs.start("bad", [sys.executable, "-c", "import sys; print('boom'); sys.exit(5)"], dict(os.environ),
                    may_exit=True)
        with pytest.raises(RuntimeError, match="bad exited with code 5:\nboom"):
            procs.wait("bad", 20)


def test_stop_all_ends_the_children_too(tmp_path):
    code = ("import subprocess, sys, time; p = subprocess.Popen([sys.executable, '-c', 'import time; "
            "time.sleep(60)']); print(p.pid, flush=True); time.sleep(60)")
    procs = Procs(tmp_path)
    procs.start("parent", [sys.executable, "-c", code], dict(os.environ))
    wait_until(lambda: (tmp_path / "parent.log").read_text().strip() != "", 20, "the child's pid")
    child = int((tmp_path / "parent.log").read_text().split()[0])
    procs.stop_all()
    end = time.monotonic() + 10
    while time.monotonic() < end and _alive(child):
        time.sleep(0.05)
    assert not _alive(child)
    assert procs.procs == []


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


def test_wait_until_times_out_naming_what():
    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match="waiting for the moon"):
        wait_until(lambda: False, 0.3, "the moon")
    assert time.monotonic() - t0 >= 0.3


def test_commands_and_interpreters():
    assert raf_cmd("sim", "--seed", "1") == [sys.executable, "-m", "robotatfactory", "sim", "--seed", "1"]
    assert raf_cmd("bridge", python="/x/python")[:3] == ["/x/python", "-m", "robotatfactory"]
    from robotatfactory.ros import mw

    for m in mw.available():  # this interpreter runs its own middleware
        assert str(interpreter(m)) == sys.executable


def test_a_killed_process_restarted_under_its_name_is_the_one_watched_with_its_own_log(tmp_path):
    """The faults campaign's use: kill a process (its whole group, no second signal) and start it again under
    the same name: numbered logs keep both runs, and only the latest process of a name is judged."""
    sleeper = [sys.executable, "-c", "import sys, time; print('run', sys.argv[1], flush=True); time.sleep(60)"]
    with Procs(tmp_path, env=dict(os.environ), numbered_logs=True) as procs:
        procs.start("node", sleeper + ["1"])
        wait_until(lambda: "run 1" in procs.log("node"), 20, "the first run's output")
        first = procs.get("node")
        procs.kill("node")
        assert first.poll() is not None and "node" in procs
        with pytest.raises(RuntimeError, match="node exited early"):
            procs.check()  # killed and not restarted: a dead process
        procs.start("node", sleeper + ["2"])
        wait_until(lambda: "run 2" in procs.log("node"), 20, "the second run's output")
        procs.check()  # the restarted one is alive: no error for the killed one
        assert procs.get("node") is not first and procs.starts["node"] == 2
        assert procs.log_path("node").name == "node.2.log" and "run 1" not in procs.log("node")
        assert "run 1" in (tmp_path / "node.1.log").read_text()
        second = procs.get("node")
    assert second.poll() is not None  # stopped with the context


def test_stop_all_signals_every_process_before_waiting_for_any(tmp_path):
    # each takes 0.6 s to shut down after its SIGINT and notes when the signal came and when it left: stopped
    # one after the other the second's signal would come after the first had left
    code = ("import signal, sys, time\n"
            "def bye(*_):\n"
            "    print('got', time.time(), flush=True); time.sleep(0.6); print('left', time.time(), flush=True)\n"
            "    sys.exit(0)\n"
            "signal.signal(signal.SIGINT, bye)\n"
            "print('up', flush=True)\n"
            "time.sleep(60)\n")
    procs = Procs(tmp_path)
    for name in ("a", "b", "c"):
        procs.start(name, [sys.executable, "-c", code], dict(os.environ))
    for name in ("a", "b", "c"):
        wait_until(lambda n=name: "up" in (tmp_path / f"{n}.log").read_text(), 20, f"{name} to start")
    procs.stop_all()
    times = {}
    for name in ("a", "b", "c"):
        for line in (tmp_path / f"{name}.log").read_text().split("\n"):
            if line.startswith(("got", "left")):
                what, t = line.split()
                times[name, what] = float(t)
    assert len(times) == 6, times
    assert max(times[n, "got"] for n in "abc") < min(times[n, "left"] for n in "abc")
