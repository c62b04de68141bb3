"""Running a ROS graph from a benchmark or an experiment: ``raf`` processes and this process's own node.

One helper for what the benchmarks and experiments all do: start ``python -m robotatfactory ...`` (the
simulator, the bridge, the localization) with a private graph's environment (:func:`.master.private_graph`),
each logging to a file of its own and in a process group of its own; notice one that died; kill one (a crash)
and start it again; stop them all.
:class:`ExperimentNode` is the experiment's own node in this process, on either middleware (ROS 2's is
spun by a thread of its own, and torn down before the interpreter exits).

Which interpreter runs a middleware: :func:`interpreter` (``.venv`` for ROS 1, ``.venv-ros2`` for ROS 2, or
this one when it has that middleware).
"""
from __future__ import annotations

import os
import signal
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
    """The processes of one run: each logs to a file in ``log_dir`` and runs in a session of its own, so that
    :meth:`stop_all` (SIGINT, then SIGKILL) ends it with its children. Use as a context manager.

    ``env``: the environment of every start that does not give its own (None: this process's). A name may be
    started again (a restart, e.g. after :meth:`kill`): :meth:`get`, :meth:`check`, :meth:`kill`, :meth:`log`
    and :meth:`tail` mean its latest process. Logs: ``NAME.log`` (a restart writes over it), or with
    ``numbered_logs`` ``NAME.N.log`` for the N-th start of ``NAME`` (1, 2, ...: every start's log is kept).
    """

    def __init__(self, log_dir: Path, watch: tuple[str, ...] | None = None, env: dict | None = None,
                 numbered_logs: bool = False):
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: list[tuple[str, subprocess.Popen]] = []  # every start, in order (a restarted name: twice)
        self.watch = watch  # names whose early exit is an error (default: every one started by start())
        self.env = env
        self.numbered_logs = numbered_logs
        self.starts: dict[str, int] = {}  # how many times each name was started
        self._expected_exit: set[str] = set()

    def log_path(self, name: str) -> Path:
        """The log of the latest start of ``name`` (of the first one when it was never started)."""
        if self.numbered_logs:
            return self.log_dir / f"{name}.{self.starts.get(name, 1)}.log"
        return self.log_dir / f"{name}.log"

    def start(self, name: str, cmd: list[str], env: dict | None = None, may_exit: bool = False) -> subprocess.Popen:
        """Start ``cmd`` (e.g. :func:`raf_cmd`) with ``env`` (default: the constructor's); ``may_exit``: its
        exit is not an error."""
        self.starts[name] = self.starts.get(name, 0) + 1
        log = open(self.log_path(name), "wb")
        try:
            p = subprocess.Popen(cmd, env=self.env if env is None else env, stdout=log, stderr=subprocess.STDOUT,
                                 start_new_session=True)
        finally:
            log.close()  # the child has its own copy
        self.procs.append((name, p))
        if may_exit:
            self._expected_exit.add(name)
        return p

    def raf(self, name: str, *args: str, env: dict | None = None, python: str | Path | None = None,
            may_exit: bool = False) -> subprocess.Popen:
        """Start ``raf ARGS`` (this interpreter unless ``python``) as process ``name``."""
        return self.start(name, raf_cmd(*args, python=python), env, may_exit)

    def get(self, name: str) -> subprocess.Popen:
        """The latest process started as ``name`` (KeyError when none was)."""
        for n, p in reversed(self.procs):
            if n == name:
                return p
        raise KeyError(name)

    def __contains__(self, name: str) -> bool:
        return any(n == name for n, _p in self.procs)

    def check(self) -> None:
        """RuntimeError (with the log's tail) when a watched process has exited (the latest of each name: one
        that was restarted is judged by its new process)."""
        latest = dict(self.procs)  # each name once, in the order of its first start; its latest process
        for name, p in latest.items():
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

    def log(self, name: str) -> str:
        """The whole log of ``name``'s latest start ("" when there is none)."""
        try:
            return self.log_path(name).read_text(errors="replace")
        except OSError:
            return ""

    def tail(self, name: str, n: int = 25) -> str:
        return "\n".join(self.log(name).splitlines()[-n:])

    def kill(self, name: str, sig: int = signal.SIGKILL, timeout: float = 10.0) -> None:
        """Send ``sig`` (default SIGKILL: a crash) to the session of ``name``'s latest process and wait up to
        ``timeout`` s for it to exit; nothing when it is not running (or was never started). Unlike
        :meth:`stop`, no second signal."""
        if name not in self:
            return
        p = self.get(name)
        if p.poll() is None:
            os.killpg(p.pid, sig)
            p.wait(timeout)

    def stop(self, name: str) -> int | None:
        from .master import stop_process

        return stop_process(self.get(name))

    def stop_all(self) -> None:
        """Stop every process: all are signalled (the last started first), then waited for together."""
        from ..proc import stop_processes

        stop_processes([p for _name, p in reversed(self.procs)])
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
