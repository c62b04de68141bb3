"""proc.free_port: ports no other process takes between the choice and the bind (parallel runs had lost runs and
tests to "Address already in use": the kernel's bind(0) hands the same ephemeral ports to everyone)."""
import socket
import subprocess
import sys
import textwrap

import pytest

import robotatfactory.proc as proc


def test_ports_lie_outside_the_kernels_ephemeral_range_and_the_private_ros2_domains():
    lo, hi = proc.ephemeral_range()
    ports = proc.leasable_ports()
    assert len(ports) > 1000
    assert not [p for p in ports if lo <= p <= hi or p < proc.PORT_FLOOR]
    for domain in (1, 37, 100):  # a private ROS 2 domain's discovery and first participants' unicast ports
        base = proc.DDS_BASE + proc.DDS_DOMAIN_GAIN * domain
        assert not {base, base + 1, base + 10, base + 11, base + 40} & set(ports)


def test_a_port_given_out_binds_for_tcp_and_udp_and_is_not_given_out_twice():
    got = [proc.free_port(socket.SOCK_DGRAM) for _ in range(50)]
    assert len(set(got)) == 50
    assert set(got) <= set(proc.leasable_ports())
    for kind in (socket.SOCK_STREAM, socket.SOCK_DGRAM):
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", got[-1]))


def _few(n: int) -> tuple[int, ...]:
    """``n`` leasable ports that nobody holds now."""
    out = []
    for p in proc.leasable_ports()[::-97]:
        if p not in proc._leases and proc._bindable(p):
            fh = proc.lease(f"raf-port-{p}")
            if fh is not None:
                fh.close()
                out.append(p)
        if len(out) == n:
            return tuple(out)
    raise AssertionError("no free ports to test with")


def test_another_process_never_gets_a_port_this_one_leased_and_gets_it_once_this_one_has_ended(monkeypatch):
    pool = _few(5)
    monkeypatch.setattr(proc, "leasable_ports", lambda: pool)
    child = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        import robotatfactory.proc as proc
        proc.leasable_ports = lambda: {pool!r}
        print(*[proc.free_port() for _ in range(3)], flush=True)
        sys.stdin.read()  # holds its leases until told to end
        """)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        theirs = set(map(int, child.stdout.readline().split()))
        assert len(theirs) == 3 and theirs <= set(pool)
        ours = {proc.free_port(), proc.free_port()}
        assert ours == set(pool) - theirs
        with pytest.raises(RuntimeError, match="no free port in 5 leasable ones"):
            proc.free_port()
    finally:
        child.stdin.close()
        child.wait(20)
    assert proc.free_port() in theirs  # the kernel dropped the ended process's leases


def test_a_port_bound_by_a_stranger_is_skipped(monkeypatch):
    pool = _few(2)
    monkeypatch.setattr(proc, "leasable_ports", lambda: pool)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as stranger:  # no lease, just bound (UDP only)
        stranger.bind(("127.0.0.1", pool[0]))
        assert proc.free_port(socket.SOCK_STREAM) == pool[1]  # the lease covers both protocols
    assert proc.free_port() == pool[0]


def test_one_process_keeps_at_most_max_leases_the_oldest_go_first(monkeypatch):
    pool = _few(4)
    monkeypatch.setattr(proc, "leasable_ports", lambda: pool)
    monkeypatch.setattr(proc, "MAX_LEASES", 3)
    monkeypatch.setattr(proc, "_leases", type(proc._leases)())
    first = proc.free_port()
    for _ in range(3):
        proc.free_port()
    assert first not in proc._leases and len(proc._leases) == 3
    fh = proc.lease(f"raf-port-{first}")  # released: another process could lease it now
    assert fh is not None
    fh.close()
