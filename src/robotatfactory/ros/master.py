"""A private ROS graph for benchmarks, experiments and tests: ROS 1's master (``roscore -p PORT``) on a free
port, or ROS 2's domain id of its own (:class:`PrivateDomain`); :func:`private_graph` picks by middleware.

Never the default port 11311: several runs (and a user's own roscore) can coexist on one machine.
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

from ..proc import free_port, stop_process  # noqa: F401  (re-exported: callers import them from here)

ROOT = Path(__file__).resolve().parents[3]  # the repository (package.xml lives here)


class _PrivateGraph:
    """What both kinds of private graph share: a private home folder (logs) removed by ``cleanup``, and use as
    a context manager. Subclasses define ``start``, ``stop``, ``env`` and ``use_in_this_process``."""

    home: Path

    def start(self):
        raise NotImplementedError

    def stop(self) -> None:
        raise NotImplementedError

    def cleanup(self) -> None:
        self.stop()
        shutil.rmtree(self.home, ignore_errors=True)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.cleanup()


class PrivateMaster(_PrivateGraph):
    """``roscore -p PORT`` in its own process group with a private ROS_HOME (logs); ``env()`` for children."""

    def __init__(self, port: int | None = None):
        self.port = port or free_port()
        self.home = Path(tempfile.mkdtemp(prefix="raf-ros-"))
        self.proc: subprocess.Popen | None = None

    @property
    def uri(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def env(self, **extra) -> dict:
        e = dict(os.environ)
        e.update(ROS_MASTER_URI=self.uri, ROS_HOME=str(self.home), ROS_LOG_DIR=str(self.home / "log"),
                 ROS_IP="127.0.0.1", PYTHONUNBUFFERED="1", RAF_MIDDLEWARE="ros1",
                 ROS_PACKAGE_PATH=os.pathsep.join(p for p in (str(ROOT), os.environ.get("ROS_PACKAGE_PATH", "")) if p))
        e.pop("ROS_HOSTNAME", None)
        e.update({k: str(v) for k, v in extra.items()})
        return e

    def use_in_this_process(self) -> None:
        """Point this process's rospy (before ``init_node``) at this master."""
        for k in ("ROS_MASTER_URI", "ROS_HOME", "ROS_LOG_DIR", "ROS_IP", "ROS_PACKAGE_PATH"):
            os.environ[k] = self.env()[k]

    def start(self, timeout: float = 20.0) -> "PrivateMaster":
        if shutil.which("roscore") is None:
            from ..errors import ConfigError

            raise ConfigError("roscore is not installed (Debian: apt install ros-core; see scripts/bootstrap.sh)")
        for _ in range(3):
            self.proc = subprocess.Popen(["roscore", "-p", str(self.port)], env=self.env(), stdout=subprocess.DEVNULL,
                                         stderr=subprocess.DEVNULL, start_new_session=True)
            if self._wait_ready(timeout):
                return self
            self.stop()
            self.port = free_port()  # taken meanwhile: try another
        raise RuntimeError("roscore did not start")

    def _wait_ready(self, timeout: float) -> bool:
        import xmlrpc.client

        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.proc.poll() is not None:
                return False
            try:
                code, _, _ = xmlrpc.client.ServerProxy(self.uri).getPid("/raf")
                if code == 1:
                    return True
            except OSError:
                pass
            except xmlrpc.client.Fault:  # another XML-RPC server on the port (a restart reuses it): not the master
                pass
            time.sleep(0.1)
        return False

    def stop(self) -> None:
        if self.proc is not None:
            stop_process(self.proc, signal.SIGINT)
        self.proc = None


def ensure_master(start_private: bool, who: str) -> "PrivateMaster | None":
    """For ``raf bridge``/``raf localize``: start a private roscore when asked, then insist a master answers.

    Returns the started master (the caller stops it) or None; raises ConfigError when no master is online.
    """
    from .mw import api

    master = None
    if start_private:
        master = PrivateMaster().start()
        os.environ["ROS_MASTER_URI"] = master.uri
        print(f"raf {who}: started roscore at {master.uri} (export ROS_MASTER_URI={master.uri})", flush=True)
    api().require_master("start roscore (or pass --roscore)")
    return master


class PrivateDomain(_PrivateGraph):
    """ROS 2's counterpart of :class:`PrivateMaster`: a ROS domain id of its own (ROS 2 has no master;
    nodes find each other by discovery, which a private ``ROS_DOMAIN_ID`` and the LOCALHOST discovery range
    keep to this run). The id is reserved with a lock file, so parallel runs on one machine never share one."""

    IDS = range(1, 101)  # valid for Fast DDS with any participant count on loopback

    def __init__(self, domain_id: int | None = None):
        self.domain_id = domain_id
        self._lock = None
        self.home = Path(tempfile.mkdtemp(prefix="raf-ros2-"))

    def start(self) -> "PrivateDomain":
        import random

        from ..proc import lease

        ids = [self.domain_id] if self.domain_id is not None else random.sample(list(self.IDS), len(self.IDS))
        for i in ids:
            fh = lease(f"raf-ros2-domain-{i}")
            if fh is not None:
                self.domain_id, self._lock = i, fh
                return self
        raise RuntimeError("no free ROS 2 domain id (every one in 1-100 is held by another run)")

    @property
    def uri(self) -> str:
        return f"ROS_DOMAIN_ID={self.domain_id}"

    def env(self, **extra) -> dict:
        e = dict(os.environ)
        e.update(ROS_DOMAIN_ID=str(self.domain_id), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
                 ROS_LOG_DIR=str(self.home / "log"), RAF_MIDDLEWARE="ros2", PYTHONUNBUFFERED="1")
        e.update({k: str(v) for k, v in extra.items()})
        return e

    def use_in_this_process(self) -> None:
        for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOG_DIR", "RAF_MIDDLEWARE"):
            os.environ[k] = self.env()[k]

    def stop(self) -> None:
        if self._lock is not None:
            self._lock.close()
            self._lock = None


def private_graph(middleware: str | None = None) -> "PrivateMaster | PrivateDomain":
    """A private ROS graph for this process's middleware (or ``middleware``), not yet started: a roscore on a
    free port (ROS 1) or a free domain id (ROS 2)."""
    from .mw import has_master

    return PrivateMaster() if has_master(middleware) else PrivateDomain()
