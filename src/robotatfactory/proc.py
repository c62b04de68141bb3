"""Child processes, without ROS: a free local port, and stopping a process group.

Used by the ROS layer (``ros/master``, ``ros/processes``) and by the real SimTwo's runner (``simtwo_linux``).
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import time


def free_port(kind=socket.SOCK_STREAM) -> int:
    """A port on 127.0.0.1 that is free now (``kind``: SOCK_STREAM for TCP, SOCK_DGRAM for UDP)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop_process(proc: subprocess.Popen, sig=signal.SIGINT, timeout: float = 10.0) -> int | None:
    """Signal a process started with ``start_new_session=True`` (its whole group), then kill it if needed."""
    return stop_processes([proc], sig, timeout)[0]


def stop_processes(procs: list[subprocess.Popen], sig=signal.SIGINT, timeout: float = 10.0) -> list[int | None]:
    """:func:`stop_process` for several at once: every group is signalled first, then each gets what is left of
    ``timeout`` s to exit before it is killed (their shutdowns overlap: a node's half second each adds up)."""
    for proc in procs:
        if proc.poll() is None:
            try:
                os.killpg(proc.pid, sig)
            except ProcessLookupError:
                pass
    end = time.monotonic() + timeout
    codes = []
    for proc in procs:
        try:
            codes.append(proc.wait(max(0.0, end - time.monotonic())))
        except subprocess.TimeoutExpired:
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            codes.append(proc.wait(5))
    return codes
