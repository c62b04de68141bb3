"""Child processes, without ROS: a free local port leased to this process, and stopping a process group.

Used by the ROS layer (``ros/master``, ``ros/processes``) and by the real SimTwo's runner (``simtwo_linux``).
"""
from __future__ import annotations

import collections
import fcntl
import functools
import os
import random
import signal
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path


#: Ports :func:`free_port` hands out: below 20000 sit well-known services (ROS 1's master at 11311 among them)
PORT_FLOOR = 20000
#: ROS 2 (Fast DDS, RTPS's port formula): domain d's participants bind 7400 + 250 d + offsets below this; the
#: private domains (ros.master.PrivateDomain) are 1-100, so their ports lie in [7650, 32650)
DDS_BASE, DDS_DOMAIN_GAIN, DDS_DOMAINS, DDS_USED = 7400, 250, 101, 150
#: Leases one process keeps at most; the oldest goes first (its port has long been bound by its user)
MAX_LEASES = 512
_leases: "collections.OrderedDict[int, object]" = collections.OrderedDict()
_lease_lock = threading.Lock()


def ephemeral_range() -> tuple[int, int]:
    """The kernel's range for ``bind(port 0)`` and outgoing sockets (Linux's default 32768-60999)."""
    try:
        lo, hi = Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()
        return int(lo), int(hi)
    except (OSError, ValueError):
        return 32768, 60999


@functools.cache
def leasable_ports() -> tuple[int, ...]:
    """The ports :func:`free_port` chooses from: at least :data:`PORT_FLOOR`, outside the kernel's ephemeral range
    (no ``bind(0)`` of any process, a ROS node's XML-RPC or TCPROS server, a DDS sender, can take one) and
    outside the unicast ports of ROS 2's private domains."""
    lo, hi = ephemeral_range()

    def dds(p: int) -> bool:
        d, off = divmod(p - DDS_BASE, DDS_DOMAIN_GAIN)
        return 0 <= d < DDS_DOMAINS and off < DDS_USED

    return tuple(p for p in range(PORT_FLOOR, 65536) if not lo <= p <= hi and not dds(p))


def _bindable(port: int) -> bool:
    for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        with socket.socket(socket.AF_INET, kind) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                return False
    return True


def lease(name: str):
    """A lease of ``name`` for this process: the open file ``$TMPDIR/{name}.lock`` with an exclusive ``flock`` (the
    kernel drops it when the process ends, however it ends; closing the file gives it back), or None while another
    process holds it. Free ports (:func:`free_port`) and ROS 2 domain ids (ros.master.PrivateDomain) are leased so."""
    fh = open(Path(tempfile.gettempdir()) / f"{name}.lock", "a")
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        return None
    return fh


def free_port(kind=socket.SOCK_STREAM) -> int:
    """A port on 127.0.0.1 that is free now, both for TCP and UDP, and leased to this process, so that no other
    run of the project picks it too before its user binds it (``kind`` is kept for the callers' sake: the lease
    covers both).

    Why not the kernel's ``bind(0)``: its port comes from the ephemeral range, where any process's next
    ``bind(0)`` may take it between the choice and the child's bind (parallel runs hit "Address already in use").
    The ports here come from :func:`leasable_ports`, where nothing binds by chance, and each is leased with a
    lock file (``$TMPDIR/raf-port-N.lock``, the way ros.master.PrivateDomain leases a domain id) for as long as
    this process lives, or until :data:`MAX_LEASES` newer leases push it out."""
    del kind
    ports = leasable_ports()
    with _lease_lock:
        start = random.randrange(len(ports))  # parallel runs start apart
        for port in ports[start:] + ports[:start]:
            if port in _leases:
                continue
            fh = lease(f"raf-port-{port}")
            if fh is None:
                continue
            if not _bindable(port):
                fh.close()
                continue
            _leases[port] = fh
            while len(_leases) > MAX_LEASES:
                _leases.popitem(last=False)[1].close()
            return port
    raise RuntimeError(f"no free port in {len(ports)} leasable ones (raf-port-*.lock in {tempfile.gettempdir()})")


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
