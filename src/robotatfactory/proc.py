"""Child processes, without ROS: a free local port, and stopping a process group.

Used by the ROS layer (``ros/master``, ``ros/processes``) and by the real SimTwo's runner (``simtwo_linux``).
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess


def free_port(kind=socket.SOCK_STREAM) -> int:
    """A port on 127.0.0.1 that is free now (``kind``: SOCK_STREAM for TCP, SOCK_DGRAM for UDP)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop_process(proc: subprocess.Popen, sig=signal.SIGINT, timeout: float = 10.0) -> int | None:
    """Signal a process started with ``start_new_session=True`` (its whole group), then kill it if needed."""
    if proc.poll() is not None:
        return proc.returncode
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        return proc.poll()
    try:
        return proc.wait(timeout)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        return proc.wait(5)
