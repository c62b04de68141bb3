"""Running a ROS graph from a benchmark or an experiment: ``raf`` processes and this process's own node.

One helper for what the benchmarks and experiments all do: start ``python -m robotatfactory ...`` (the
simulator, the bridge, the localization) with a private graph's environment (:func:`.master.private_graph`),
each logging to a file of its own and in a process group of its own; notice one that died; stop them all.
:class:`ExperimentNode` is the experiment's own node in this process, on either middleware (ROS 2's is
spun by a thread of its own, and torn down before the interpreter exits).

Which interpreter runs a middleware: :func:`interpreter` (``.venv`` for ROS 1, ``.venv-ros2`` for ROS 2, or
this one when it has that middleware).
"""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[3]
#: each middleware's virtual environment in the repository (scripts/bootstrap.sh builds both; ``raf
#: --middleware`` and :func:`interpreter` run its Python)
VENVS = {"ros1": ".venv", "ros2": ".venv-ros2"}


def interpreter(middleware: str) -> Path | None:
    """The Python that runs ``middleware`` (this one when it can import it), or None when it is not there."""
    from .mw import importable

    if importable(middleware):
        return Path(sys.executable)
    if middleware == "ros2" and os.environ.get("RAF_ROS2_VENV"):
        venv = Path(os.environ["RAF_ROS2_VENV"])
    else:
        venv = ROOT / VENVS[middleware]
    py = venv / "bin" / "python"
    return py if py.exists() else None


def raf_cmd(*args: str, python: str | Path | None = None) -> list[str]:
    """The command line of ``raf ARGS`` run by ``python`` (default: this interpreter)."""
    return [str(python or sys.executable), "-m", "robotatfactory", *args]


def wait_until(pred: Callable[[], bool], timeout: float, what: str, check: Callable[[], None] | None = None,
               period: float = 0.05) -> None:
    """Poll ``pred()`` until true; RuntimeError naming ``what`` after ``timeout`` s. ``check()`` runs each
    round (e.g. :meth:`Procs.check`, which raises when a process died)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if pred():
            return
        if check is not None:
            check()
        time.sleep(period)
    raise RuntimeError(f"timed out after {timeout:.0f} s waiting for {what}")


class Procs:
    """The processes of one run: each logs to ``log_dir/NAME.log`` and runs in a session of its own, so that
    :meth:`stop_all` (SIGINT, then SIGKILL) ends it with its children. Use as a context manager."""

    def __init__(self, log_dir: Path, watch: tuple[str, ...] | None = None):
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: list[tuple[str, subprocess.Popen]] = []
        self.watch = watch  # names whose early exit is an error (default: every one started by start())
        self._expected_exit: set[str] = set()

    def start(self, name: str, cmd: list[str], env: dict, may_exit: bool = False) -> subprocess.Popen:
        """Start ``cmd`` (e.g. :func:`raf_cmd`) with ``env``; ``may_exit``: its exit is not an error."""
        log = open(self.log_dir / f"{name}.log", "wb")
        try:
            p = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        finally:
            log.close()  # the child has its own copy
        self.procs.append((name, p))
        if may_exit:
            self._expected_exit.add(name)
        return p

    def raf(self, name: str, *args: str, env: dict, python: str | Path | None = None,
            may_exit: bool = False) -> subprocess.Popen:
        """Start ``raf ARGS`` (this interpreter unless ``python``) as process ``name``."""
        return self.start(name, raf_cmd(*args, python=python), env, may_exit)

    def get(self, name: str) -> subprocess.Popen:
        for n, p in reversed(self.procs):
            if n == name:
                return p
        raise KeyError(name)

    def check(self) -> None:
        """RuntimeError (with the log's tail) when a watched process has exited."""
        for name, p in self.procs:
            if name in self._expected_exit or (self.watch is not None and name not in self.watch):
                continue
            if p.poll() is not None:
                raise RuntimeError(f"{name} exited early with code {p.returncode}:\n{self.tail(name)}")

    def wait(self, name: str, timeout: float) -> int:
        """Wait for process ``name`` to exit; RuntimeError with its log's tail when it fails or times out."""
        p = self.get(name)
        try:
            code = p.wait(timeout)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"{name} still running after {timeout:.0f} s:\n{self.tail(name)}") from None
        if code != 0:
            raise RuntimeError(f"{name} exited with code {code}:\n{self.tail(name)}")
        return code

    def tail(self, name: str, n: int = 25) -> str:
        try:
            return "\n".join((self.log_dir / f"{name}.log").read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return ""

    def stop(self, name: str) -> int | None:
        from .master import stop_process

        return stop_process(self.get(name))

    def stop_all(self) -> None:
        """Stop every process, the last started first."""
        from .master import stop_process

        for _name, p in reversed(self.procs):
            stop_process(p)
        self.procs.clear()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop_all()


class ExperimentNode:
    """This process's node on its middleware (:mod:`.mw`), with its callbacks served in the background:
    rospy has threads of its own; rclpy's executor is spun by a daemon thread here. ``close()`` (or the
    context manager) shuts it down; for ROS 2 that is required before the interpreter exits.

    Call after the graph's ``use_in_this_process()``. ``node`` is the :class:`~.mw.base.Node`.
    """

    def __init__(self, name: str):
        from .mw import api

        self.mw = api()
        self.node = self.mw.init_node(name, argv=[sys.argv[0]], anonymous=True, signals=False)
        self._thread: threading.Thread | None = self.node.spin_in_background(f"raf-{name}-spin")

    @property
    def middleware(self) -> str:
        return self.mw.NAME

    def drop(self, handle) -> None:
        """Unsubscribe a subscription or remove a publisher made on this node (either middleware; None and
        twice do nothing)."""
        self.node.close(handle)

    def wait_for_message(self, topic: str, msg_type, timeout: float, qos=None):
        """One message on ``topic`` (None after ``timeout`` s)."""
        from .mw import QoS

        got: list = []
        ev = threading.Event()

        def cb(m):
            if not got:
                got.append(m)
                ev.set()

        sub = self.node.subscribe(topic, msg_type, cb, qos or QoS.RELIABLE, 1, large=True)
        try:
            ev.wait(timeout)
        finally:
            self.drop(sub)
        return got[0] if got else None

    def close(self) -> None:
        self.node.finish(spinner=self._thread)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
